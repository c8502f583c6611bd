"""Hostile input: nothing a user passed in is lost, nothing wrong is reported as success.

One group per class of fault: outputs that would overwrite inputs, results that depend on the
units, memory spent before a refusal, success claimed for what the data does not support,
signals and full disks during output, internal errors for ordinary bad input, misleading
messages. Every run is tiny (resolution 16 to 24, a few iterations).
"""

import hashlib
import json
import os
import resource
import subprocess
import sys
import threading
import zipfile
from pathlib import Path

import numpy as np
import pytest

import warpspec as ws
from warpspec.cli import main
from warpspec.evaluate import DistanceStats, Evaluation
from warpspec.solver import load_state, save_state
from warpspec.verdict import SUPPORT_RADIUS

ROOT = Path(__file__).resolve().parents[1]
OCTANT = ROOT / "examples" / "scenes" / "octant.json"
OCTANT_TRUTH = ROOT / "examples" / "scenes" / "octant.ply"
OCTANT_TRUTH_JSON = ROOT / "examples" / "scenes" / "octant.truth.json"
FAST = ["--resolution", "16", "--iterations", "6", "--start", "paper", "--bulge", "0.5",
        "--device", "cpu", "--quiet"]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    return status, capsys.readouterr().err


def assert_error(status, err, field, code=2):
    assert status == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], err
    assert "Traceback" not in err and "internal error" not in err, err


def no_temps(folder: Path) -> bool:
    return not [p.name for p in folder.iterdir() if p.name.startswith(".")]


def octant_data() -> dict:
    return json.loads(OCTANT.read_text())


def scaled(data: dict, s: float) -> dict:
    """The scene with every length multiplied by ``s`` (P = K[R|t] becomes K[R/s | t])."""
    data = json.loads(json.dumps(data))
    for cam in data["cameras"]:
        P = np.array(cam["P"])
        P[:, :3] /= s
        cam["P"] = P.tolist()
    data["points"] = (np.array(data["points"]) * s).tolist()
    data["domain"] = {k: (np.array(v) * s).tolist() for k, v in data["domain"].items()}
    for light in [data.get("light")] + [c.get("light") for c in data["cameras"]]:
        if light and light.get("type") == "point":
            light["position"] = (np.array(light["position"]) * s).tolist()
    return data


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "octant.json").write_bytes(OCTANT.read_bytes())
    return tmp_path


# -- 1. outputs never overwrite inputs --------------------------------------------------------


def test_metrics_onto_the_scene_is_refused_and_the_scene_kept(capsys, folder):
    scene = folder / "octant.json"
    before = digest(scene)
    status, err = run(capsys, "reconstruct", scene, "-o", folder / "m.ply", "--metrics", scene,
                      *FAST)
    assert_error(status, err, "--metrics")
    assert "input file" in err and digest(scene) == before


def test_a_scene_named_ply_is_not_replaced_by_the_mesh(capsys, folder):
    scene = folder / "scene.ply"
    scene.write_bytes(OCTANT.read_bytes())
    before = digest(scene)
    status, err = run(capsys, "reconstruct", scene, "-o", scene, *FAST)
    assert_error(status, err, "--output")
    assert digest(scene) == before


def test_a_hard_link_to_the_scene_is_an_input_too(capsys, folder):
    scene = folder / "octant.json"
    os.link(scene, folder / "link.json")
    before = digest(scene)
    status, err = run(capsys, "reconstruct", scene, "-o", folder / "x.ply",
                      "--metrics", folder / "link.json", *FAST)
    assert_error(status, err, "--metrics")
    assert digest(scene) == before and not (folder / "x.ply").exists()


@pytest.mark.parametrize("victim", ["--truth-json", "--scene"])
def test_evaluate_json_onto_an_input_is_refused(capsys, tmp_path, victim):
    truth_json = tmp_path / "t.json"
    truth_json.write_bytes(OCTANT_TRUTH_JSON.read_bytes())
    scene = tmp_path / "s.json"
    scene.write_bytes(OCTANT.read_bytes())
    target = truth_json if victim == "--truth-json" else scene
    before = digest(target)
    status, err = run(capsys, "evaluate", OCTANT_TRUTH, "--truth", OCTANT_TRUTH,
                      "--truth-json", truth_json, "--scene", scene, "--json", target)
    assert_error(status, err, "--json")
    assert digest(target) == before


def _limited(limit: int):
    def preexec():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def test_scene_save_onto_itself_on_a_full_disk_keeps_the_original(tmp_path):
    path = tmp_path / "scene.json"
    path.write_bytes(OCTANT.read_bytes())
    before = digest(path)
    code = ("import warpspec as ws, sys; s = ws.Scene.load(sys.argv[1])\n"
            "import numpy as np\n"
            "big = ws.Scene(s.cameras, s.spec_camera, s.spec_pixel,"
            " np.random.default_rng(0).random((20000, 3)), light=s.light, domain=s.domain)\n"
            "try:\n    big.save(sys.argv[1])\nexcept ws.SceneError as e:\n"
            "    print(e); sys.exit(2)\n")
    done = subprocess.run([sys.executable, "-c", code, str(path)], env=ENV, text=True,
                          capture_output=True, timeout=120, preexec_fn=_limited(100_000),
                          check=False)
    assert done.returncode == 2, done.stderr
    assert "cannot write the scene file" in done.stdout
    assert digest(path) == before and no_temps(tmp_path)


# -- 2. the units do not change the result ----------------------------------------------------


@pytest.fixture(scope="module")
def unit_runs():
    """The octant at three scales; the paper's start (start="paper") keeps it short."""
    out = {}
    for s in (1.0, 1e-6, 1e9):
        scene = ws.Scene.from_dict(scaled(octant_data(), s))
        out[s] = ws.reconstruct(scene, iterations=10, resolution=24, start="paper", bulge=0.5,
                                device="cpu")
    return out


@pytest.mark.parametrize("s", [1e-6, 1e9])
def test_a_scaled_scene_gives_the_same_mesh_scaled(unit_runs, s):
    ref, run_ = unit_runs[1.0], unit_runs[s]
    assert len(ref.faces) > 500
    # Merged in grid units: no vertex collapses at 1e-6, no key overflows at 1e9.
    assert run_.vertices.shape == ref.vertices.shape
    assert np.array_equal(run_.faces, ref.faces)
    extent = np.ptp(ref.vertices, axis=0).max()
    assert np.abs(run_.vertices / s - ref.vertices).max() <= 1e-5 * extent
    # The support map and the verdict are in voxel widths: the same numbers.
    assert np.abs(run_.support - ref.support).max() <= 1e-3
    assert run_.verdict.supported and ref.verdict.supported
    assert abs(run_.verdict.normal_error_deg - ref.verdict.normal_error_deg) <= 1e-2


def test_vertices_merge_in_grid_units_at_any_scale():
    from warpspec.mesh import triangulate

    for s in (1e-9, 1.0, 1e11):
        grid = ws.Grid(origin=np.full(3, -s), spacing=2 * s / 16, shape=(17, 17, 17))
        x, y, z = grid.coordinates()
        phi = np.sqrt(x**2 + y**2 + z**2) - 0.6 * s
        verts, faces = triangulate(phi, grid)
        # A closed sphere: Euler characteristic 2 (V - E + F = V - F/2), no collapsed face.
        assert len(verts) - len(faces) // 2 == 2, s
        assert np.allclose(np.linalg.norm(verts, axis=1), 0.6 * s, rtol=0.05)


# -- 3. bounded memory in the number of points --------------------------------------------


@pytest.mark.slow
def test_a_million_point_scene_loads_and_validates_in_bounded_memory(tmp_path):
    path = tmp_path / "big.json"
    data = octant_data()
    data.pop("domain")
    rng = np.random.default_rng(0)
    data["points"] = np.round(rng.random((1_000_000, 3)), 4).tolist()
    path.write_text(json.dumps(data))
    code = ("import resource, sys, warnings, warpspec as ws\n"
            "warnings.simplefilter('ignore')\n"
            "s = ws.Scene.load(sys.argv[1]); s.check(); lo, hi = s.bounds()\n"
            "print(s.num_points, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n")
    done = subprocess.run([sys.executable, "-c", code, str(path)], env=ENV, text=True,
                          capture_output=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    count, peak_kib = (int(v) for v in done.stdout.split())
    assert count == 1_000_000
    # An N x N matrix would need 8 TB; the parsed JSON and the arrays take a few hundred MB.
    assert peak_kib < 2**20, f"peak {peak_kib / 2**20:.2f} GiB"  # measured: 0.36 GiB


# -- 4. no success claimed for what the data does not support --------------------------------


def _rays_miss(data):
    """Every ray misses: each highlight moved far off its image, where the camera looks past
    the domain; the points stay inside it."""
    for spec in data["specularities"]:
        spec["pixel"] = [-1.0e4, -1.0e4]


def test_every_ray_missing_exits_3_and_writes_nothing(capsys, tmp_path):
    data = octant_data()
    _rays_miss(data)
    scene = tmp_path / "miss.json"
    scene.write_text(json.dumps(data))
    report = tmp_path / "run.json"
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", *FAST,
                      "--report", report)
    assert status == 3, err
    assert "NOT supported by the data: 0 of 24 specular rays meet the surface" in err
    assert not (tmp_path / "x.ply").exists()
    # the report says why, and that no mesh was written
    record = json.loads(report.read_text())
    assert record["mesh"] is None and not record["verdict"]["supported"]
    assert record["verdict"]["hit_fraction"] == 0.0
    assert any("specular rays meet the surface" in r for r in record["verdict"]["reasons"])
    report.unlink()
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", *FAST,
                      "--keep-unsupported")
    assert status == 0, err
    assert "NOT supported" in err and "written anyway" in err
    assert (tmp_path / "x.ply").stat().st_size > 100


def test_the_verdict_is_on_the_result_through_the_api():
    data = octant_data()
    _rays_miss(data)
    result = ws.reconstruct(ws.Scene.from_dict(data), iterations=3, resolution=16,
                            device="cpu")
    v = result.verdict
    assert not v.supported and v.hit_fraction == 0.0 and v.rays == 24
    assert "NOT supported" in repr(result) and "array" not in repr(result)


@pytest.mark.parametrize("points", [True, False], ids=["points-outside", "no-points"])
def test_a_domain_that_holds_nothing_names_the_domain(capsys, tmp_path, points):
    """No point inside the domain and no ray entering it: nothing to reconstruct there."""
    data = octant_data()
    if not points:
        data["points"] = []
    data["domain"] = {"min": [20.0, 20.0, 20.0], "max": [21.0, 21.0, 21.0]}
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(data))
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", *FAST)
    assert_error(status, err, "domain: ")
    assert f"none of the scene's {len(data['points'])} points" in err
    assert "give a domain around the object" in err and not (tmp_path / "x.ply").exists()
    with pytest.raises(ws.InputError, match="^grid: the box"):
        ws.Reconstructor(ws.Scene.from_dict(data), device="cpu", grid=ws.Grid(
            origin=np.full(3, 20.0), spacing=0.1, shape=(11, 11, 11)))


def test_no_constraint_on_the_surface_is_named():
    """Rays that enter the domain but meet no surface there, and no points."""
    from warpspec.grid import Grid
    from warpspec.verdict import assess

    grid = Grid(origin=np.full(3, -1.0), spacing=0.1, shape=(21, 21, 21))
    x, _, _ = grid.coordinates()
    phi = x + 0.5  # a sheet at x = -0.5; the rays run along it, beside it
    origins = np.array([[0.5, 0.0, 3.0], [0.2, 0.3, 3.0]])
    dirs = np.tile([0.0, 0.0, -1.0], (2, 1))
    hits = np.full((2, 3), np.nan)
    vertices = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.5, 0.0], [-0.5, 0.0, 0.5]])
    v, support = assess(phi=phi, grid=grid, vertices=vertices, hits=hits,
                        demanded_normals=None, points=np.zeros((0, 3)),
                        camera_rays=(origins, dirs))
    assert not v.supported and v.hit_fraction == 0.0
    assert any("no constraint is on the surface" in r for r in v.reasons)
    assert np.all(np.isinf(support))


def test_resume_on_another_scenes_grid_is_refused(capsys, folder):
    phi = folder / "phi.npz"
    assert main(["reconstruct", str(folder / "octant.json"), "-o", str(folder / "a.ply"),
                 "--save-phi", str(phi), *FAST]) == 0
    far = scaled(octant_data(), 1.0)
    far["points"] = (np.array(far["points"]) + 50.0).tolist()
    far["domain"] = {k: (np.array(v) + 50.0).tolist() for k, v in far["domain"].items()}
    other = folder / "far.json"
    other.write_text(json.dumps(far))
    capsys.readouterr()
    status, err = run(capsys, "reconstruct", other, "-o", folder / "b.ply", "--resume", phi,
                      *FAST)
    assert_error(status, err, "--resume: ")
    assert "resume only with the scene it was saved from" in err


def test_a_resumed_run_says_so(capsys, folder):
    phi = folder / "phi.npz"
    scene = folder / "octant.json"
    assert main(["reconstruct", str(scene), "-o", str(folder / "a.ply"), "--save-phi",
                 str(phi), *FAST]) == 0
    fast = [a for a in FAST if a != "--quiet"]
    status, err = run(capsys, "reconstruct", scene, "-o", folder / "b.ply", "--resume", phi,
                      *fast)
    assert status == 0 and f"(resumed from {phi})" in err


def test_evaluate_without_any_normal_says_so_instead_of_nan():
    stats = DistanceStats.of(np.array([0.1, 0.2]))
    table = Evaluation(accuracy=stats, completeness=stats, spacing=0.1, cropped=False,
                       normal_angle_mean=None, normal_angle_max=None,
                       normal_angles=np.zeros(0)).table()
    assert "nan" not in table and "not measured" in table


@pytest.mark.parametrize("resolution", [10**6, 10**20, 2**64])
def test_an_absurd_resolution_is_refused_not_shrunk(resolution):
    scene = ws.Scene.load(OCTANT)
    with pytest.raises(ws.InputError, match="^resolution: must be at most 2048"):
        ws.Reconstructor(scene, resolution=resolution, device="cpu")


def test_redistance_beyond_float32_gives_finite_distances():
    from tests.helpers import cube_grid, sphere_sdf

    grid = cube_grid(20)
    exact = sphere_sdf(grid, (0.1, 0.0, 0.0), 0.5)
    for scale in (1e40, 1e-40):
        d = ws.redistance(exact * scale, grid.spacing * scale, device="cpu")
        assert np.all(np.isfinite(d))
        near = np.abs(exact) < 3 * grid.spacing
        assert np.abs(d[near] / scale - exact[near]).max() < 0.5 * grid.spacing


# -- 5. signals, full disks, long names, concurrent writers ---------------------------------


_PATCHED_RUN = """
import os, signal, sys
# as started from a terminal: a test runner started in the background passes SIGINT ignored
signal.signal(signal.SIGINT, signal.default_int_handler)
import warpspec.mesh
def write_ply(path, vertices, faces, **kwargs):
    open(path, "wb").write(b"ply\\nformat ascii 1.0\\nelement vertex 99")  # half a mesh
    os.kill(os.getpid(), getattr(signal, sys.argv[1]))
    raise SystemExit("the signal did not stop the write")
warpspec.mesh.write_ply = write_ply
from warpspec.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize(("name", "status"), [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_during_output_leaves_the_inputs_and_no_temporary_file(folder, name, status):
    scene = folder / "octant.json"
    before = digest(scene)
    (folder / "old.ply").write_bytes(b"the previous mesh")
    argv = ["reconstruct", str(scene), "-o", str(folder / "old.ply"), "--metrics",
            str(folder / "m.csv"), *FAST]
    done = subprocess.run([sys.executable, "-c", _PATCHED_RUN, name, *argv], env=ENV,
                          text=True, capture_output=True, timeout=300, check=False)
    assert done.returncode == status, done.stderr
    assert done.stderr.strip().endswith("no output was written"), done.stderr
    assert digest(scene) == before
    assert (folder / "old.ply").read_bytes() == b"the previous mesh"
    assert sorted(p.name for p in folder.iterdir()) == ["octant.json", "old.ply"]


def test_a_long_legal_output_name_works(capsys, folder):
    name = "m" * 250 + ".ply"  # 254 bytes: legal, and no temporary name may be longer
    status, err = run(capsys, "reconstruct", folder / "octant.json", "-o", folder / name,
                      *FAST)
    assert status == 0, err
    assert (folder / name).stat().st_size > 100 and no_temps(folder)


def test_synth_on_a_full_disk_writes_nothing_and_names_the_file(tmp_path):
    argv = [sys.executable, "-m", "warpspec", "synth", "octant", "-o", str(tmp_path / "s.json"),
            "--truth", str(tmp_path / "t.ply"), "--truth-json", str(tmp_path / "t.json")]
    done = subprocess.run(argv, env=ENV, text=True, capture_output=True, timeout=300,
                          preexec_fn=_limited(30_000), check=False)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot write" in lines[0] and str(tmp_path) in lines[0]
    assert list(tmp_path.iterdir()) == []  # neither the scene without its truth, nor temps


def test_concurrent_saves_to_one_path_do_not_collide(tmp_path):
    grid = ws.Grid(origin=np.zeros(3), spacing=0.1, shape=(12, 12, 12))
    path = tmp_path / "phi.npz"
    errors = []

    def save(k):
        try:
            for _ in range(5):
                save_state(path, np.full(grid.shape, float(k) - 0.5, dtype=np.float32), grid)
        except Exception as exc:  # noqa: BLE001 - any failure is the finding
            errors.append(exc)

    threads = [threading.Thread(target=save, args=(k,)) for k in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    phi, _ = load_state(path)
    assert len(np.unique(phi)) == 1  # one writer's whole file, not a mixture
    assert [p.name for p in tmp_path.iterdir()] == ["phi.npz"]


# -- 6. memory is not spent before a refusal --------------------------------------------------


def _npz(path: Path, phi_header_shape, phi_bytes: int, grid_shape=(4, 4, 4)):
    """An NPZ whose phi.npy declares one shape and holds ``phi_bytes`` of zeros."""
    header = {"descr": "<f4", "fortran_order": False, "shape": tuple(phi_header_shape)}
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        with z.open("phi.npy", "w", force_zip64=True) as f:
            f.write(np.lib.format.MAGIC_PREFIX + b"\x01\x00")
            text = repr(header).encode("latin1")
            pad = 64 - (len(np.lib.format.MAGIC_PREFIX) + 4 + len(text) + 1) % 64
            text += b" " * pad + b"\n"
            f.write(len(text).to_bytes(2, "little") + text)
            chunk = bytes(2**20)
            left = phi_bytes
            while left > 0:
                f.write(chunk[:min(left, len(chunk))])
                left -= len(chunk)
        for key, value in (("origin", np.zeros(3)), ("spacing", np.float64(0.1)),
                           ("shape", np.array(grid_shape))):
            with z.open(f"{key}.npy", "w") as f:
                np.lib.format.write_array(f, np.asarray(value))


def test_a_level_set_claiming_a_trillion_values_is_refused_unread(tmp_path):
    path = tmp_path / "huge.npz"
    _npz(path, (10_000, 10_000, 10_000), 256)
    with pytest.raises(ws.InputError, match="too large: 'phi' is declared"):
        load_state(path)


def test_a_compressed_bomb_is_refused_before_it_expands(tmp_path):
    path = tmp_path / "bomb.npz"
    _npz(path, (4, 4, 4), 200 * 2**20)  # 200 MiB of zeros in a file of about 200 KiB
    assert path.stat().st_size < 2**20
    with pytest.raises(ws.InputError, match=r"expands to 2097153\d\d bytes, more than its "
                                             r"shape \(4, 4, 4\)"):
        load_state(path)


def test_a_scene_file_too_large_is_refused_before_reading(tmp_path, monkeypatch):
    monkeypatch.setattr("warpspec.scene.MAX_SCENE_BYTES", 1000)
    with pytest.raises(ws.InputError, match=r"above the limit of 0 MiB"):
        ws.Scene.load(OCTANT)


def test_evaluate_samples_are_bounded(capsys):
    status, err = run(capsys, "evaluate", OCTANT_TRUTH, "--truth", OCTANT_TRUTH,
                      "--samples", 10**12)
    assert_error(status, err, "--samples: must be between 100 and 10000000")


# -- 7. ordinary bad input is an input error, not a bug ---------------------------------------


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated", b"not a zip at all"])
def test_a_broken_level_set_exits_2(capsys, folder, content):
    bad = folder / "bad.npz"
    bad.write_bytes(content)
    status, err = run(capsys, "reconstruct", folder / "octant.json", "-o", folder / "x.ply",
                      "--resume", bad, *FAST)
    assert_error(status, err, "--resume: ")


def test_a_truncated_level_set_exits_2(capsys, folder):
    good = folder / "phi.npz"
    save_state(good, np.ones((8, 8, 8), dtype=np.float32) - 0.5,
               ws.Grid(origin=np.zeros(3), spacing=0.2, shape=(8, 8, 8)))
    (folder / "cut.npz").write_bytes(good.read_bytes()[:-40])
    status, err = run(capsys, "reconstruct", folder / "octant.json", "-o", folder / "x.ply",
                      "--resume", folder / "cut.npz", *FAST)
    assert_error(status, err, "--resume: ")


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d.update(domain={"min": [-1e150] * 3, "max": [1e150] * 3}), "domain: "),
        (lambda d: d.update(domain={"min": [0.0] * 3, "max": [1e-300] * 3}), "domain: "),
        (lambda d: d.update(domain={"min": [1e9] * 3, "max": [1e9 + 1] * 3}), "domain: "),
    ],
    ids=["huge", "tiny", "far-from-origin"],
)
def test_absurd_coordinates_name_the_domain(capsys, tmp_path, edit, field):
    data = octant_data()
    edit(data)
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(data))
    status, err = run(capsys, "reconstruct", scene, "-o", tmp_path / "x.ply", *FAST)
    assert_error(status, err, field)
    assert "cfl" not in err and "point_weight" not in err


def test_a_resolution_whose_node_count_overflows_is_an_input_error():
    with pytest.raises(ws.InputError, match="more than the .* Warp can index"):
        ws.Grid(origin=np.zeros(3), spacing=1.0, shape=(10**7, 10**7, 10**7))


def test_negative_seed_and_bad_indices_in_evaluate_exit_2(capsys, tmp_path):
    status, err = run(capsys, "evaluate", OCTANT_TRUTH, "--truth", OCTANT_TRUTH, "--seed", -3)
    assert_error(status, err, "--seed")
    truth = json.loads(OCTANT_TRUTH_JSON.read_text())
    truth["outliers"] = [999]
    bad = tmp_path / "t.json"
    bad.write_text(json.dumps(truth))
    status, err = run(capsys, "evaluate", OCTANT_TRUTH, "--truth", OCTANT_TRUTH,
                      "--truth-json", bad)
    assert_error(status, err, "'outliers'")
    for name, text in (
        ("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 99\n"),
        ("bad.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nelement face 2\n"
                    "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n"
                    "0 1 0\n3 0 1 2\n3 0 1 99\n"),
    ):
        (tmp_path / name).write_text(text)
        status, err = run(capsys, "evaluate", tmp_path / name, "--truth", OCTANT_TRUTH)
        assert_error(status, err, "MESH: ")
        assert "out of" in err  # out of bounds, out of range: the indices are named


@pytest.mark.parametrize(("option", "value"), [("resume", 123), ("grid", "abc")])
def test_the_api_names_a_wrong_type(option, value):
    with pytest.raises(ws.InputError, match=f"^{option}: expected"):
        ws.reconstruct(OCTANT, iterations=1, resolution=16, device="cpu", **{option: value})


# -- 8. messages that name the real cause ------------------------------------------------------


@pytest.mark.parametrize(("flag", "value"), [("--alpha", "1e30"), ("--bulge", "1e30"),
                                             ("--bulge", "-1e30")])
def test_absurd_weights_are_named(capsys, folder, flag, value):
    status, err = run(capsys, "reconstruct", folder / "octant.json", "-o", folder / "x.ply",
                      *FAST, f"{flag}={value}")
    assert_error(status, err, f"{flag}: must be")


def test_one_warning_per_ray_is_summarised(capsys, tmp_path):
    data = octant_data()
    # 24 cameras, each with 10 highlights in its top-left corner: rays that miss the domain.
    data["specularities"] += [{"camera": c, "pixel": [1.0 + k, 1.0]}
                              for c in range(24) for k in range(10)]
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(data))
    fast = [a for a in FAST if a != "--quiet"]
    main(["reconstruct", str(scene), "-o", str(tmp_path / "x.ply"), *fast,
          "--keep-unsupported"])
    err = capsys.readouterr().err
    never = [line for line in err.splitlines() if "never enters" in line]
    assert 1 <= len(never) <= 3, err
    assert "more like the above" in err
    assert len(err.splitlines()) < 20, err


def test_numpy_warnings_do_not_leak(capsys, folder):
    status, err = run(capsys, "reconstruct", folder / "octant.json", "-o", folder / "x.ply",
                      *FAST)
    assert status == 0 and "RuntimeWarning" not in err and err == ""


# -- the support map ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def octant_result():
    return ws.reconstruct(OCTANT, iterations=8, resolution=20, device="cpu")


def test_support_is_the_distance_to_the_nearest_constraint_in_voxels(octant_result):
    r = octant_result
    scene = ws.Scene.load(OCTANT)
    anchors = r.constraint_anchors(scene)
    brute = np.min(np.linalg.norm(r.vertices[:, None] - anchors[None], axis=2), axis=1)
    assert np.allclose(r.support, brute / r.grid.spacing, rtol=1e-9, atol=1e-9)
    v = r.verdict
    assert v.supported and v.hit_fraction == 1.0 and v.normal_error_deg < 5
    assert v.point_distance < 0.5
    assert v.supported_fraction == pytest.approx(np.mean(r.support <= SUPPORT_RADIUS))


def test_the_ply_carries_support_and_crop_support_keeps_the_supported_faces(capsys, folder):
    import trimesh

    scene = folder / "octant.json"
    assert main(["reconstruct", str(scene), "-o", str(folder / "all.ply"), *FAST]) == 0
    assert main(["reconstruct", str(scene), "-o", str(folder / "crop.ply"), "--crop", "support",
                 *FAST]) == 0
    full = trimesh.load(folder / "all.ply", process=False)
    crop = trimesh.load(folder / "crop.ply", process=False)
    s_full = np.asarray(full.metadata["_ply_raw"]["vertex"]["data"]["support"])
    s_crop = np.asarray(crop.metadata["_ply_raw"]["vertex"]["data"]["support"])
    assert len(s_full) == len(full.vertices) and s_full.max() > SUPPORT_RADIUS
    assert 0 < len(crop.faces) < len(full.faces)
    assert s_crop.max() <= SUPPORT_RADIUS + 1e-6


def test_reprs_are_short(octant_result):
    for obj in (octant_result, octant_result.grid, ws.Scene.load(OCTANT)):
        text = repr(obj)
        assert len(text) < 200 and "\n" not in text and "array" not in text, text


def test_a_level_set_larger_than_free_memory_is_refused_unread(tmp_path, monkeypatch):
    path = tmp_path / "big.npz"
    _npz(path, (600, 600, 600), 256, grid_shape=(600, 600, 600))  # declares 864 MB
    pages = {"SC_AVPHYS_PAGES": 2**18, "SC_PAGE_SIZE": 4096}  # 1 GiB free
    monkeypatch.setattr("os.sysconf", lambda name: pages[name])
    with pytest.raises(ws.InputError, match=r"needs 1\.6 GiB to read, but only 1\.0 GiB"):
        load_state(path)


def test_a_points_only_scene_is_judged_by_its_points():
    data = octant_data()
    data["specularities"] = []
    result = ws.reconstruct(ws.Scene.from_dict(data), iterations=4, resolution=16,
                            device="cpu")
    v = result.verdict
    assert v.rays == 0 and np.isnan(v.hit_fraction) and np.isnan(v.normal_error_deg)
    assert v.supported and v.point_distance < 0.5
    assert "no specular rays" in v.summary() and "nan" not in v.summary()


def test_written_files_follow_the_umask(folder):
    old = os.umask(0o027)
    try:
        ws.Scene.load(OCTANT).save(folder / "copy.json")
    finally:
        os.umask(old)
    # The mask was read when the package was imported; the file gets 0o666 minus that mask.
    from warpspec._atomic import _UMASK

    assert (folder / "copy.json").stat().st_mode & 0o777 == 0o666 & ~_UMASK


def test_a_scene_without_points_is_not_supported():
    """Highlights alone fix the shape, not the depth: the verdict says so."""
    data = json.loads(OCTANT.read_text())
    data["points"] = []
    scene = ws.Scene.from_dict(data)
    result = ws.reconstruct(scene, iterations=5, resolution=20, start="paper", device="cpu")
    assert not result.verdict.supported
    assert any("no point constraints" in r for r in result.verdict.reasons)


@pytest.mark.parametrize("s", [1e-6, 1e9])
@pytest.mark.parametrize("name", ["point-light", "bottle", "torus"])
def test_the_default_start_is_free_of_units_too(s, name):
    """The implicit start at 1e-6 and 1e9 gives the mesh scaled: the quadric and the grid fit
    (the point-lit dome), the surface of revolution (the bottle), the ring torus."""
    from warpspec.synthetic import make_scene

    data = make_scene(name).scene_dict
    ref = ws.reconstruct(ws.Scene.from_dict(data), iterations=10, resolution=24, device="cpu")
    run_ = ws.reconstruct(ws.Scene.from_dict(scaled(data, s)), iterations=10, resolution=24,
                          device="cpu")
    extent = np.ptp(ref.vertices, axis=0).max()
    if name == "point-light":
        assert run_.vertices.shape == ref.vertices.shape
        assert np.array_equal(run_.faces, ref.faces)
        assert np.abs(run_.vertices / s - ref.vertices).max() <= 1e-5 * extent
    else:
        # a node within rounding of the zero set may add or drop a vertex: the same surface
        from scipy.spatial import cKDTree

        a, b = run_.vertices / s, ref.vertices
        assert abs(len(a) - len(b)) <= 0.01 * len(b)
        assert cKDTree(b).query(a)[0].max() <= 1e-3 * extent
        assert cKDTree(a).query(b)[0].max() <= 1e-3 * extent


def _inside_verdict(phi, grid, origins, dirs, hits):
    from warpspec.verdict import assess

    v, _ = assess(phi=phi, grid=grid, vertices=hits, hits=hits, demanded_normals=None,
                  points=hits[-1:], camera_rays=(origins, dirs))
    return v


def test_rays_that_reach_their_hits_from_inside_the_surface_are_not_supported():
    """A camera sees the object from outside: a level set that holds the rays' entry into the
    domain inside it (here the sphere's complement) contradicts every view."""
    from warpspec.grid import Grid
    from warpspec.verdict import MAX_INSIDE_FRACTION, assess

    grid = Grid(origin=np.full(3, -1.0), spacing=0.05, shape=(41, 41, 41))
    x, y, z = grid.coordinates()
    sphere = np.sqrt(x**2 + y**2 + z**2) - 0.5
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.0, 0.8], [0.0, 0.0, -1.0]])
    origins = -3.0 * dirs
    hits = -0.5 * dirs
    for phi, inside in ((sphere, 0.0), (-sphere, 1.0)):
        v = _inside_verdict(phi, grid, origins, dirs, hits)
        assert v.inside_fraction == inside
        assert v.supported == (inside <= MAX_INSIDE_FRACTION)
    assert any("enter the domain inside it" in r for r in v.reasons)
    # without the rays the check is skipped
    v, _ = assess(phi=-sphere, grid=grid, vertices=hits, hits=hits, demanded_normals=None,
                  points=hits[:1])
    assert v.supported and np.isnan(v.inside_fraction)


def test_the_inside_check_at_the_domain_faces_and_for_few_rays():
    """A sheet a fifth of a voxel below the box's top face, rays straight down onto it: their
    hits lie nearer than half a voxel, and sampling there would put them inside. A ray along a
    face, a camera inside the box, a ray that misses the box: outside. Two rays of eleven from
    inside pass; three fail."""
    from warpspec.grid import Grid
    from warpspec.verdict import MIN_INSIDE_RAYS

    grid = Grid(origin=np.zeros(3), spacing=0.1, shape=(11, 11, 11))
    _, _, z = grid.coordinates()
    top = 0.98
    phi = z - top  # below the sheet is inside
    down = np.array([0.0, 0.0, -1.0])
    xy = np.linspace(0.1, 0.9, 11)
    origins = np.column_stack([xy, np.full(11, 0.5), np.full(11, 3.0)])
    dirs = np.tile(down, (11, 1))
    hits = origins + (3.0 - top) * dirs
    v = _inside_verdict(phi, grid, origins, dirs, hits)
    assert v.inside_fraction == 0.0 and v.supported
    # along the top face, from inside the box, and missing it altogether: all outside
    odd_o = np.array([[-1.0, 0.5, 1.0], [0.5, 0.5, 0.99], [5.0, 5.0, 5.0]])
    odd_d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    odd_h = np.array([[0.5, 0.5, 1.0], [0.5, 0.5, top], [0.5, 0.5, top]])
    v = _inside_verdict(phi, grid, odd_o, odd_d, odd_h)
    assert v.inside_fraction == 0.0
    # rays that enter through a side face below the sheet come from inside
    for count, supported in ((MIN_INSIDE_RAYS - 1, True), (MIN_INSIDE_RAYS, False)):
        o, d, h = origins.copy(), dirs.copy(), hits.copy()
        o[:count] = [-1.0, 0.5, 0.5]
        d[:count] = [1.0, 0.0, 0.0]
        h[:count] = [0.5, 0.5, 0.5]
        v = _inside_verdict(phi, grid, o, d, h)
        assert v.inside_fraction == pytest.approx(count / 11)
        assert v.supported == supported


@pytest.mark.parametrize("name", ["octant", "wine-bottle", "sphere-around", "torus", "bottle",
                                  "wrap", "freeform", "point-light"])
def test_the_truth_is_reached_from_outside_by_every_ray(name):
    """The check passes the truth itself: its implicit function on the grid, the true hits."""
    from warpspec.grid import Grid
    from warpspec.synthetic import make_scene

    synthetic = make_scene(name)
    scene = synthetic.scene()
    lo, hi = scene.domain
    grid = Grid.from_bounds(lo, hi, resolution=48)
    nodes = np.stack(grid.coordinates(), axis=-1).reshape(-1, 3)
    phi = synthetic.surface.implicit(nodes).reshape(grid.shape)
    origins, dirs = scene.rays()
    v = _inside_verdict(phi, grid, origins, dirs, synthetic.truth_points)
    assert v.inside_fraction == 0.0


def test_a_bottle_lost_under_lamps_is_not_reported_as_supported(monkeypatch):
    """Lamps, cameras on one ring above, a quarter of false highlights (seed 0): the first axis
    is 45 degrees off, and without the cameras' ring as a second first axis no surface of
    revolution is found; the grid fit's fat open blob (4-6 voxels off) meets the normals it
    keeps, but either a few of the rays that meet it enter the domain inside it (5 of 34), or
    too few meet it (20 of 36, in the solver's frame about the grid's centre): not supported.
    The check that catches it depends on the blob's last digits; both are tested alone above. No
    trial of its rejected rays is made (it misses the kept normals by 15 degrees, median):
    the trial's extra ladder bent it on until it looked supported. The quadric fits are ranked
    as before they were told apart by the rays that enter them from inside: since, the fit
    taken gives a true first axis, and the bottle is found (0.03 voxels off)."""
    import warpspec.implicit as implicit
    from warpspec import quadric
    from warpspec.synthetic import make_scene
    from warpspec.verdict import MAX_INSIDE_FRACTION, MIN_HIT_FRACTION

    monkeypatch.setattr(implicit, "camera_ring", lambda centres: None)
    monkeypatch.setattr(quadric.Quadric, "entered_from_inside",
                        lambda self, origins, *_: np.zeros(len(origins), dtype=bool))
    synthetic = make_scene("bottle-lamps", rings=1, outliers=0.25)
    result = ws.reconstruct(synthetic.scene(), resolution=64, device="cpu")
    err = np.abs(synthetic.surface.implicit(result.vertices)).mean() / result.grid.spacing
    assert err > 2.0
    assert not result.verdict.supported
    v = result.verdict
    assert v.inside_fraction > MAX_INSIDE_FRACTION or v.hit_fraction < MIN_HIT_FRACTION
    assert any("enter the domain inside it" in r or "specular rays meet the surface" in r
               for r in v.reasons)
