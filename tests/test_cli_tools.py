"""``warpspec synth`` and ``warpspec evaluate``, run in-process through ``warpspec.cli.main``."""

import json

import numpy as np
import pytest
import trimesh

from warpspec.cli import main
from warpspec.grid import Grid
from warpspec.scene import Scene
from warpspec.synthetic import make_scene


def run(args, capsys):
    """Exit status, stdout and stderr of ``warpspec ARGS`` (argparse's exits included)."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def octant_files(tmp_path_factory):
    """The octant written once by ``warpspec synth`` with its truth mesh and truth data."""
    folder = tmp_path_factory.mktemp("octant")
    paths = {k: folder / n for k, n in (("scene", "octant.json"), ("mesh", "octant.ply"),
                                         ("truth", "octant.truth.json"))}
    assert main(["synth", "octant", "-o", str(paths["scene"]), "--truth", str(paths["mesh"]),
                 "--truth-json", str(paths["truth"]), "--quiet"]) == 0
    return paths


def test_synth_writes_a_loadable_scene_with_its_truth(octant_files):
    scene = Scene.load(octant_files["scene"])
    synthetic = make_scene("octant")
    assert scene.num_specularities == 24 and scene.num_points == 3
    np.testing.assert_allclose(scene.points, np.eye(3))
    truth = json.loads(octant_files["truth"].read_text())
    x = np.asarray(truth["truth_points"])
    np.testing.assert_allclose(x, synthetic.truth_points, atol=1e-12)
    np.testing.assert_allclose(truth["points"], np.eye(3))
    # The rays rebuilt from the written file pass through the true points ...
    origins, dirs = scene.rays()
    off = np.linalg.norm(np.cross(x - origins, dirs), axis=1)
    assert off.max() < 1e-9
    # ... and the reflection law there gives the true normals.
    np.testing.assert_allclose(scene.normals(x), truth["truth_normals"], atol=1e-9)
    mesh = trimesh.load(octant_files["mesh"], force="mesh")
    assert len(mesh.faces) > 1000
    assert mesh.area == pytest.approx(np.pi / 2, rel=5e-3)
    # No temporary file is left beside the outputs.
    assert sorted(p.name for p in octant_files["scene"].parent.iterdir()) == [
        "octant.json", "octant.ply", "octant.truth.json"]


def test_synth_noise_is_seeded(tmp_path, capsys):
    a, b, c = (tmp_path / n for n in ("a.json", "b.json", "c.json"))
    for path, seed in ((a, 1), (b, 1), (c, 2)):
        code, _, err = run(["synth", "car-window", "-o", path, "--noise", 0.5, "--outliers",
                            0.1, "--seed", seed], capsys)
        assert code == 0
    assert "38 specularities (4 outliers, noise 0.5 px)" in err
    assert a.read_text() == b.read_text() != c.read_text()
    clean = make_scene("car-window")
    pixels = np.array([s["pixel"] for s in json.loads(a.read_text())["specularities"]])
    assert 0 < np.abs(pixels - clean.pixels).max()


def test_synth_point_noise_moves_only_the_points(tmp_path, capsys):
    a, b, t = (tmp_path / n for n in ("a.json", "b.json", "t.json"))
    code, _, err = run(["synth", "torus", "-o", a, "--point-noise", 1, "--seed", 4,
                        "--truth-json", t], capsys)
    assert code == 0 and "points (noise 1 voxel)" in err
    assert run(["synth", "torus", "-o", b, "--seed", 4], capsys)[0] == 0
    noisy, plain = json.loads(a.read_text()), json.loads(b.read_text())
    assert noisy["specularities"] == plain["specularities"]
    moved = np.abs(np.subtract(noisy["points"], plain["points"])).max()
    voxel = max(np.subtract(plain["domain"]["max"], plain["domain"]["min"])) / 64
    assert 0.2 * voxel < moved < 6 * voxel
    assert json.loads(t.read_text())["clean_points"] == plain["points"]
    code, _, err = run(["synth", "torus", "-o", tmp_path / "c.json", "--point-noise", -1],
                       capsys)
    assert code != 0 and "--point-noise" in err and not (tmp_path / "c.json").exists()


def test_evaluate_truth_against_itself_prints_zeros(octant_files, capsys, tmp_path):
    report = tmp_path / "eval.json"
    code, out, err = run(["evaluate", octant_files["mesh"], "--truth", octant_files["mesh"],
                          "--scene", octant_files["scene"], "--json", report], capsys)
    assert code == 0, err
    for figure in ("accuracy (mesh to truth)", "completeness (truth to mesh)", "Chamfer",
                   "symmetric mean", "Hausdorff", "Normal angle", "voxel width h"):
        assert figure in out
    data = json.loads(report.read_text())
    assert data["chamfer"] < 1e-12 and data["hausdorff"] < 1e-12
    assert data["cropped"] is True
    # The true specular points are where the 24 rays meet the truth mesh.
    assert data["normal_angle_deg"]["count"] == 24
    assert data["normal_angle_deg"]["max"] < 1e-6
    lo, hi = Scene.load(octant_files["scene"]).bounds()
    assert data["spacing"] == pytest.approx(Grid.from_bounds(lo, hi, resolution=64).spacing)


def test_evaluate_gives_the_offset_of_a_scaled_octant(octant_files, capsys, tmp_path):
    """A sphere of radius 1 + delta against the unit sphere: every distance is delta."""
    delta = 0.01
    truth = trimesh.load(octant_files["mesh"], force="mesh")
    grown = trimesh.Trimesh(truth.vertices * (1 + delta), truth.faces, process=False)
    path = tmp_path / "grown.ply"
    grown.export(path)
    report = tmp_path / "eval.json"
    code, out, _ = run(["evaluate", path, "--truth", octant_files["mesh"], "--truth-json",
                        octant_files["truth"], "--spacing", 0.02, "--json", report], capsys)
    assert code == 0
    data = json.loads(report.read_text())
    # Flat facets of the truth mesh sit up to ~1e-4 inside the sphere: a small tolerance.
    for side in ("completeness", "accuracy"):
        assert data[side]["mean"] == pytest.approx(delta, abs=3e-4)
        assert data[f"{side}_voxels"]["mean"] == pytest.approx(delta / 0.02, abs=0.015)
    assert data["normal_angle_deg"]["max"] < 1.5  # scaled facets keep their normals
    assert "| 0.5" in out  # the mean in voxel widths, 0.01 / 0.02


@pytest.mark.parametrize(("args", "flag"), [
    (["synth", "teapot", "-o", "{d}/s.json"], "NAME"),
    (["synth", "octant", "-o", "{d}/s.txt"], "--output"),
    (["synth", "octant", "-o", "{d}/missing/s.json"], "--output"),
    (["synth", "octant", "-o", "{d}/s.json", "--truth", "{d}/t.xyz"], "--truth"),
    (["synth", "octant", "-o", "{d}/s.json", "--noise", "-1"], "--noise"),
    (["synth", "octant", "-o", "{d}/s.json", "--outliers", "1.5"], "--outliers"),
    (["synth", "octant", "-o", "{d}/s.json", "--seed", "-3"], "--seed"),
    (["evaluate", "{d}/none.ply", "--truth", "{mesh}"], "MESH"),
    (["evaluate", "{mesh}", "--truth", "{d}/none.ply"], "--truth"),
    (["evaluate", "{mesh}", "--truth", "{mesh}", "--resolution", "32"], "--resolution"),
    (["evaluate", "{mesh}", "--truth", "{mesh}", "--spacing", "-1"], "--spacing"),
    (["evaluate", "{mesh}", "--truth", "{mesh}", "--json", "{d}/e.csv"], "--json"),
    (["evaluate", "{mesh}", "--truth", "{mesh}", "--scene", "{d}/none.json"], "--scene"),
    (["evaluate", "{mesh}", "--truth", "{mesh}", "--truth-json", "{scene}"], "--truth-json"),
    (["evaluate", "{scene}", "--truth", "{mesh}"], "MESH"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_bad_input_exits_2_and_names_the_flag(args, flag, octant_files, tmp_path, capsys):
    fill = {"d": tmp_path, "mesh": octant_files["mesh"], "scene": octant_files["scene"]}
    code, out, err = run([a.format(**fill) for a in args], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warpspec: error: ")
    assert flag in lines[0]
    assert not list(tmp_path.iterdir())  # nothing written


def test_unparsable_number_exits_2_naming_the_flag(tmp_path, capsys):
    code, _, err = run(["synth", "octant", "-o", tmp_path / "s.json", "--noise", "lots"], capsys)
    assert code == 2
    assert "--noise" in err
    assert not list(tmp_path.iterdir())


def test_help_defines_every_figure(capsys):
    code, text, _ = run(["evaluate", "--help"], capsys)
    assert code == 0
    for phrase in ("completeness", "accuracy", "symmetric mean", "Hausdorff", "95th percentile",
                   "convex hull", "normal angle", "voxel width"):
        assert phrase in text
    code, text, _ = run(["synth", "--help"], capsys)
    assert code == 0
    for name in ("octant", "car-window", "wine-bottle", "ellipsoid-cap"):
        assert name in text
