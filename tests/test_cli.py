"""The command line: one-line errors with exit status 2, outputs, resume, crop, pictures."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from warpspec.cli import main
from warpspec.solver import MEASURE_KEYS

from .test_colmap import SPECULAR, write_model

ROOT = Path(__file__).resolve().parents[1]
OCTANT = ROOT / "examples" / "scenes" / "octant.json"
# Small and quick; the octant needs the paper's bend for its rays to meet the start.
FAST = ["--resolution", "20", "--iterations", "12", "--start", "paper", "--bulge", "0.5",
        "--device", "cpu", "--quiet"]


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "octant.json"
    path.write_bytes(OCTANT.read_bytes())
    return path


def run(capsys, *argv):
    """Run ``warpspec argv`` in-process; return the exit status and standard error."""
    status = main([str(a) for a in argv])
    return status, capsys.readouterr().err


def assert_one_line_error(status, err, field):
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "error:" in lines[0] and field in lines[0], err
    assert "Traceback" not in err


def octant_with(tmp_path, edit):
    data = json.loads(OCTANT.read_text())
    edit(data)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(data))
    return path


# -- bad input: exit 2, one line naming the field --------------------------------------------


@pytest.mark.parametrize(
    ("content", "field"),
    [
        ("{", "not valid JSON"),
        ("[1, 2, 3]", "scene"),
        ('{"format": "ply", "version": 1, "cameras": []}', "format"),
        ('{"format": "warpspec-scene", "version": 2, "cameras": []}', "version"),
        ('{"format": "warpspec-scene", "version": 1, "cameras": [], "points": [[0,0,0]]}',
         "cameras"),
    ],
    ids=["not-json", "not-an-object", "format", "version", "no-cameras"],
)
def test_bad_scene_files_exit_2_naming_the_field(capsys, tmp_path, content, field):
    path = tmp_path / "bad.json"
    path.write_text(content)
    assert_one_line_error(*run(capsys, "reconstruct", path, "-o", tmp_path / "x.ply"), field)
    assert not (tmp_path / "x.ply").exists()


def _p_not_3x4(d):
    d["cameras"][0]["P"] = d["cameras"][0]["P"][:2]


def _p_singular(d):
    d["cameras"][1]["P"] = [[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 1]]


def _camera_out_of_range(d):
    d["specularities"][5]["camera"] = 99


def _pixel_not_two_numbers(d):
    d["specularities"][2]["pixel"] = [1.0, "x"]


def _zero_light(d):
    d["light"] = {"type": "directional", "direction": [0, 0, 0]}


def _unknown_light(d):
    d["light"] = {"type": "laser"}


def _inverted_domain(d):
    d["domain"] = {"min": [1, 1, 1], "max": [0, 2, 2]}


def _no_constraints(d):
    d["specularities"] = []
    d["points"] = []


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (_p_not_3x4, "cameras[0].P"),
        (_p_singular, "cameras[1].P"),
        (_camera_out_of_range, "specularities[5].camera"),
        (_pixel_not_two_numbers, "specularities[2].pixel"),
        (_zero_light, "light.direction"),
        (_unknown_light, "light.type"),
        (_inverted_domain, "domain"),
        (_no_constraints, "constraints"),
    ],
    ids=lambda v: v if isinstance(v, str) else v.__name__.strip("_"),
)
def test_bad_scene_fields_exit_2_naming_the_field(capsys, tmp_path, edit, field):
    path = octant_with(tmp_path, edit)
    assert_one_line_error(*run(capsys, "reconstruct", path, "-o", tmp_path / "x.ply"), field)


def test_a_missing_scene_file_exits_2(capsys, tmp_path):
    status, err = run(capsys, "reconstruct", tmp_path / "nope.json", "-o", tmp_path / "x.ply")
    assert_one_line_error(status, err, "no such file")
    assert "nope.json" in err


@pytest.mark.parametrize("flag", ["--resolution", "--iterations"])
@pytest.mark.parametrize("value", ["0", "-1", "abc", "2.5"])
def test_counts_must_be_positive_integers(capsys, scene, tmp_path, flag, value):
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", flag, value)
    assert_one_line_error(status, err, flag)
    assert "positive integer" in err


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["-o", "{tmp}/x.xyz"], "--output"),
        (["-o", "{tmp}/missing/x.ply"], "--output"),
        (["-o", "{tmp}/x.ply", "--metrics", "{tmp}/m.txt"], "--metrics"),
        (["-o", "{tmp}/x.ply", "--save-phi", "{tmp}/s.npy"], "--save-phi"),
        (["-o", "{tmp}/x.ply", "--render", "{tmp}/r.jpg"], "--render"),
        (["-o", "{tmp}/x.ply", "--plot", "{tmp}/nowhere/p.png"], "--plot"),
        (["-o", "{tmp}/x.ply", "--render", "{tmp}/p.png", "--plot", "{tmp}/p.png"], "--plot"),
        (["-o", "{tmp}/x.ply", "--device", "tpu"], "--device"),
        (["-o", "{tmp}/x.ply", "--resume", "{tmp}/nope.npz"], "--resume"),
        (["-o", "{tmp}/x.ply", "--alpha", "-1"], "--alpha"),
        (["-o", "{tmp}/x.ply", "--alpha", "nan"], "--alpha"),
        (["-o", "{tmp}/x.ply", "--bulge-cap", "0"], "--bulge-cap"),
        (["-o", "{tmp}/x.ply", "--reinit-every", "-2"], "--reinit-every"),
        (["-o", "{tmp}/x.ply", "--crop", "box"], "--crop"),
        (["-o", "{tmp}/x.ply", "--resolution", "2000"], "--resolution: a 2001x"),
        (["-o", "{tmp}/x.ply", "--resolution", "200000"], "--resolution: must be at most"),
        ([], "--output"),
    ],
    ids=["output-ext", "output-folder", "metrics-ext", "save-phi-ext", "render-ext",
         "plot-folder", "same-file", "device", "resume-missing", "alpha-negative", "alpha-nan",
         "bulge-cap", "reinit", "crop", "too-many-nodes", "too-large", "no-output"],
)
def test_bad_arguments_exit_2_naming_the_flag(capsys, scene, tmp_path, args, field):
    argv = [a.format(tmp=tmp_path) for a in args]
    status, err = run(capsys, "reconstruct", scene, *argv)
    assert_one_line_error(status, err, field)
    assert [p.name for p in tmp_path.iterdir()] == ["octant.json"]


def test_a_resume_file_that_is_not_a_level_set_exits_2(capsys, scene, tmp_path):
    bogus = tmp_path / "bogus.npz"
    bogus.write_bytes(b"not a zip file")
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", "--resume", bogus)
    assert_one_line_error(status, err, "--resume")


def test_usage_errors_are_one_line(capsys):
    status, err = run(capsys, "reconstrct")
    assert_one_line_error(status, err, "invalid choice")
    status, err = run(capsys)
    assert_one_line_error(status, err, "required")


def test_version_in_a_subprocess():
    done = subprocess.run([sys.executable, "-m", "warpspec", "--version"], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "warpspec 0.1.0"


def test_the_program_exits_with_the_status_and_complete_outputs(tmp_path):
    # the program skips the collector's final pass at exit: statuses and files must survive
    prog = [sys.executable, "-m", "warpspec", "reconstruct"]
    done = subprocess.run([*prog, str(tmp_path / "none.json"), "-o", str(tmp_path / "x.ply")],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and "error:" in done.stderr
    done = subprocess.run([*prog, str(OCTANT), "-o", str(tmp_path / "x.ply"), *FAST,
                           "--metrics", str(tmp_path / "m.csv")],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert len(trimesh.load(tmp_path / "x.ply").faces) > 100
    assert len((tmp_path / "m.csv").read_text().splitlines()) == 14  # header, start, 12


# -- good runs --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """One run with every output: mesh, metrics, saved level set, render and plot."""
    out = tmp_path_factory.mktemp("run")
    status = main(["reconstruct", str(OCTANT), "-o", str(out / "mesh.ply"), *FAST,
                   "--metrics", str(out / "m.csv"), "--save-phi", str(out / "phi.npz"),
                   "--render", str(out / "render.png"), "--plot", str(out / "plot.png")])
    assert status == 0
    return out


@pytest.mark.parametrize("ext", [".ply", ".obj", ".stl", ".glb"])
def test_every_mesh_format_loads_back_with_faces(capsys, tmp_path, ext):
    path = tmp_path / f"mesh{ext}"
    status, err = run(capsys, "reconstruct", OCTANT, "-o", path, *FAST)
    assert status == 0, err
    assert err == ""  # --quiet
    mesh = trimesh.load(path, force="mesh")
    assert len(mesh.faces) > 100
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no temporary left


def test_metrics_have_one_row_per_iteration_with_the_history_keys(first_run, capsys, tmp_path):
    with open(first_run / "m.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == MEASURE_KEYS
    assert [int(r["iteration"]) for r in rows] == list(range(13))  # the start, then 12
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "x.ply", *FAST,
                      "--metrics", tmp_path / "m.json")
    assert status == 0, err
    data = json.loads((tmp_path / "m.json").read_text())
    assert [r["iteration"] for r in data] == list(range(13))
    assert all(tuple(r) == MEASURE_KEYS for r in data)
    assert data[-1]["active"] + data[-1]["misses"] == 24
    # --measure-every thins the records; the start and the last iteration are always kept
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "x.ply", *FAST,
                      "--metrics", tmp_path / "m5.json", "--measure-every", "5")
    assert status == 0, err
    data5 = json.loads((tmp_path / "m5.json").read_text())
    assert [r["iteration"] for r in data5] == [0, 5, 10, 12]
    assert data5[-1] == {**data[-1], "seconds": data5[-1]["seconds"]}


def test_save_phi_then_resume_continues_from_the_saved_state(first_run, capsys, tmp_path):
    with np.load(first_run / "phi.npz") as saved:
        shape = saved["phi"].shape
    before = json.loads(json.dumps(list(csv.DictReader(open(first_run / "m.csv")))))[-1]
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "x.ply", "--iterations",
                      "5", "--device", "cpu", "--quiet", "--resume", first_run / "phi.npz",
                      "--metrics", tmp_path / "m.json", "--save-phi", tmp_path / "phi.npz")
    assert status == 0, err
    rows = json.loads((tmp_path / "m.json").read_text())
    # The resumed run starts where the first ended: same level set, same measures.
    for key in ("point_error", "energy_point", "energy_smooth", "active", "misses"):
        assert rows[0][key] == pytest.approx(float(before[key]), rel=1e-5, abs=1e-9), key
    assert len(rows) == 6
    with np.load(tmp_path / "phi.npz") as resumed:
        assert resumed["phi"].shape == shape


def test_resolution_is_ignored_with_resume_and_says_so(first_run, capsys, tmp_path):
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "x.ply", "--iterations",
                      "1", "--device", "cpu", "--resolution", "40", "--resume",
                      first_run / "phi.npz")
    assert status == 0, err
    assert "warning: --resolution is ignored with --resume" in err


def test_crop_hull_keeps_fewer_faces(first_run, capsys, tmp_path):
    whole = trimesh.load(first_run / "mesh.ply")
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "crop.ply", *FAST,
                      "--crop", "hull")
    assert status == 0, err
    cropped = trimesh.load(tmp_path / "crop.ply")
    assert 0 < len(cropped.faces) < len(whole.faces)


def test_crop_hull_and_auto_drop_the_sphere_behind_the_octant_in_a_wide_domain(capsys,
                                                                                tmp_path):
    """In a domain twice as wide, the octant's fit is the unit sphere; its back lies inside
    the constraints' hull, which is 2-D, seen along the data's normal. Neither crop keeps it:
    the faces face the data's side, ``n . (1, 1, 1) > 0`` (down to -1.7 on the back)."""
    data = json.loads(OCTANT.read_text())
    lo, hi = np.array(data["domain"]["min"]), np.array(data["domain"]["max"])
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    data["domain"] = {"min": list(centre - 2 * half), "max": list(centre + 2 * half)}
    path = tmp_path / "wide.json"
    path.write_text(json.dumps(data))
    counts = {}
    for crop in ("none", "auto", "hull"):
        out = tmp_path / f"{crop}.ply"
        status, err = run(capsys, "reconstruct", path, "-o", out, "--resolution", "32",
                          "--crop", crop, "--quiet")
        assert status == 0, err
        mesh = trimesh.load(out)
        facing = mesh.face_normals @ np.ones(3)
        counts[crop] = len(mesh.faces)
        if crop == "none":
            assert np.mean(facing < 0) > 0.1
        else:  # a rim the data's mean normal (not quite (1, 1, 1)) sees as its front
            assert facing.min() > -0.1 and np.mean(facing < 0) < 0.01
    assert counts["hull"] < counts["auto"] < counts["none"]


def test_render_and_plot_are_pngs(first_run):
    for name in ("render.png", "plot.png"):
        data = (first_run / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        assert len(data) > 10_000


def test_a_normal_run_reports_warnings_and_a_summary(capsys, tmp_path):
    status, err = run(capsys, "reconstruct", OCTANT, "-o", tmp_path / "x.ply",
                      *[a for a in FAST if a != "--quiet"])
    assert status == 0
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"warpspec: wrote {tmp_path / 'x.ply'} (")
    assert "normal error" in last and "missed rays" in last


def test_missing_matplotlib_is_refused_before_the_run(capsys, scene, tmp_path, monkeypatch):
    for name in list(sys.modules):
        if name == "matplotlib" or name.startswith("matplotlib."):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)

    def no_run(*args, **kwargs):
        raise AssertionError("the solver must not start")

    monkeypatch.setattr("warpspec.solver.Reconstructor.__init__", no_run)
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", "--render",
                      tmp_path / "r.png")
    assert_one_line_error(status, err, "--render: needs matplotlib; install it with: "
                                       "pip install 'warpspec[plot]'")


def test_the_report_lists_every_rejected_highlight(capsys, tmp_path):
    """The summary names the first rejected highlights and counts the rest; ``--report``
    writes every one (index, camera, pixel, residual), with the verdict and the start. The
    sphere seen all around by flash, a quarter of its 28 highlights false: 7 rejected, each a
    false one, by the quadric start."""
    from warpspec.synthetic import make_scene

    synthetic = make_scene("sphere-around", seed=0, outliers=0.25)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(synthetic.scene_dict))
    report = tmp_path / "run.json"
    status = main([str(a) for a in ("reconstruct", path, "-o", tmp_path / "m.ply",
                                    "--resolution", "32", "--iterations", "10",
                                    "--device", "cpu", "--report", report)])
    err = capsys.readouterr().err
    assert status == 0, err
    record = json.loads(report.read_text())
    rows = record["rejected"]
    false = set(np.flatnonzero(synthetic.outlier_mask).tolist())
    assert len(rows) > 5 and {r["index"] for r in rows} <= false
    assert f"{len(rows)} of 28 highlights rejected" in err
    assert f"and {len(rows) - 5} more (--report lists all)" in err
    scene_rows = synthetic.scene_dict["specularities"]
    for r in rows:
        assert r["camera"] == scene_rows[r["index"]]["camera"]
        assert r["pixel"] == pytest.approx(scene_rows[r["index"]]["pixel"])
        assert r["residual_deg"] > 15.0
    assert record["verdict"]["supported"] and record["verdict"]["rays"] == 28
    assert record["start"] == {"guess": "sphere", "shape": "quadric", "prior": None}
    assert record["mesh"] == str(tmp_path / "m.ply") and record["faces"] > 0
    assert record["grid"]["shape"] == [33, 33, 33] and record["iterations"] == 10


def test_info_lists_versions_devices_and_the_cache(capsys):
    status = main(["info"])
    out = capsys.readouterr().out
    assert status == 0
    assert "warp " in out and "device cpu" in out and "kernel cache" in out


# -- import-colmap ----------------------------------------------------------------------------


def test_import_colmap_writes_a_scene_that_reconstruct_reads(capsys, tmp_path):
    import warpspec as ws
    from warpspec.colmap import load_colmap

    model = tmp_path / "sparse"
    write_model(model)
    out = tmp_path / "scene.json"
    status, err = run(capsys, "import-colmap", model, "--highlights", model / "highlights.csv",
                      "--light", "camera", "-o", out, "--max-points", "4", "--points", "all",
                      "--domain", "-2", "-2", "-2", "2", "2", "2")
    assert status == 0, err
    assert "wrote" in err and "4 cameras, 4 specularities, 4 points" in err
    scene = ws.Scene.load(out)
    expected = load_colmap(model, model / "highlights.csv", light="camera", points="all",
                           max_points=4)
    np.testing.assert_array_equal(scene.cameras, expected.cameras)
    np.testing.assert_array_equal(scene.spec_pixel, expected.spec_pixel)
    origins, dirs = scene.rays()
    w = SPECULAR - origins
    miss = np.linalg.norm(w - np.einsum("ij,ij->i", w, dirs)[:, None] * dirs, axis=1)
    assert np.all(miss < 1e-6)
    data = json.loads(out.read_text())
    assert data["_images"] == ["img001.png", "img003.png", "img000.png", "img002.png"]


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--light", "sideways"], "--light"),
        (["--light", "directional:0,0,0"], "--light.direction"),
        (["--light", "camera", "--domain", "0", "0", "0", "1", "1"], "--domain"),
        (["--light", "camera", "--domain", "0", "0", "0", "1", "-1", "1"], "domain: max"),
        (["--light", "camera", "--points", "1,x"], "--points"),
        (["--light", "camera", "--pixel-convention", "centre"], "--pixel-convention"),
        ([], "light: missing"),
    ],
    ids=["light-spec", "light-zero", "domain", "domain-inverted", "points", "convention",
         "no-light"],
)
def test_import_colmap_bad_arguments_exit_2(capsys, tmp_path, args, field):
    model = tmp_path / "sparse"
    write_model(model)
    status, err = run(capsys, "import-colmap", model, "--highlights", model / "highlights.csv",
                      "-o", tmp_path / "s.json", *args)
    assert_one_line_error(status, err, field)
    assert not (tmp_path / "s.json").exists()


def test_import_colmap_names_the_bad_line(capsys, tmp_path):
    model = tmp_path / "sparse"
    write_model(model)
    (model / "highlights.csv").write_text("image,u,v\nimg000.png,12,abc\n")
    status, err = run(capsys, "import-colmap", model, "--highlights", model / "highlights.csv",
                      "--light", "camera", "-o", tmp_path / "s.json")
    assert_one_line_error(status, err, f"{model / 'highlights.csv'}:2: v: expected a number")


def test_import_colmap_undistorts_without_warnings(capsys, tmp_path):
    # Lens distortion is now undistorted (tests/test_colmap.py checks the rays), not ignored
    # with a warning.
    model = tmp_path / "sparse"
    write_model(model, model="OPENCV")
    status, err = run(capsys, "import-colmap", model, "--highlights", model / "highlights.csv",
                      "--light", "camera", "-o", tmp_path / "s.json")
    assert status == 0, err
    assert not [line for line in err.splitlines() if "warning:" in line]


def test_crop_needs_three_constraints_and_says_so_before_the_run(capsys, tmp_path):
    def two_points(d):
        d["specularities"] = []
        d["points"] = d["points"][:2]

    path = octant_with(tmp_path, two_points)
    status, err = run(capsys, "reconstruct", path, "-o", tmp_path / "x.ply", "--crop", "hull")
    assert_one_line_error(status, err, "--crop: the hull needs at least 3 constraints")


def test_a_folder_given_as_the_scene_hints_at_import_colmap(capsys, tmp_path):
    model = tmp_path / "sparse"
    write_model(model)
    status, err = run(capsys, "reconstruct", model, "-o", tmp_path / "x.ply")
    assert_one_line_error(status, err, "warpspec import-colmap")
