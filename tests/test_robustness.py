"""Failure handling: interrupted and failed runs leave nothing behind, inputs stay untouched,
runs on the CPU are bitwise reproducible."""

import copy
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import warpspec as ws
from warpspec.cli import main

ROOT = Path(__file__).resolve().parents[1]
OCTANT = ROOT / "examples" / "scenes" / "octant.json"
FAST = ["--resolution", "16", "--iterations", "8", "--start", "paper", "--bulge", "0.5",
        "--device", "cpu"]
OPTIONS = {"resolution": 16, "start": "paper", "bulge": 0.5, "device": "cpu"}


@pytest.fixture
def folder(tmp_path):
    """A folder holding only a copy of the octant scene."""
    (tmp_path / "octant.json").write_bytes(OCTANT.read_bytes())
    return tmp_path


def reconstruct_all(folder):
    """Every output the reconstruct command can write, into ``folder``."""
    return ["reconstruct", str(folder / "octant.json"), "-o", str(folder / "mesh.ply"), *FAST,
            "--metrics", str(folder / "m.csv"), "--save-phi", str(folder / "phi.npz"),
            "--render", str(folder / "render.png"), "--plot", str(folder / "plot.png")]


def only_the_scene_is_left(folder):
    return sorted(p.name for p in folder.iterdir()) == ["octant.json"]


def _interrupt_solver(monkeypatch):
    original = ws.Reconstructor.step

    def step(self, **kwargs):
        original(self, **kwargs)
        if self.iteration == 4:
            raise KeyboardInterrupt

    monkeypatch.setattr(ws.Reconstructor, "step", step)


def _interrupt_mesh_export(monkeypatch):
    def write_ply(path, vertices, faces, **kwargs):
        Path(path).write_bytes(b"ply\nformat ascii 1.0\nelement vertex 99")  # half a mesh
        raise KeyboardInterrupt

    monkeypatch.setattr("warpspec.mesh.write_ply", write_ply)


def _interrupt_level_set_save(monkeypatch):
    def savez(file, **arrays):
        file.write(b"PK\x03\x04 half a zip")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", savez)


def _interrupt_plot(monkeypatch):
    # The last output: the mesh, metrics, level set and render are complete by then.
    def plot_history(history, path, **kwargs):
        Path(path).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr("warpspec.plots.plot_history", plot_history)


@pytest.mark.parametrize("interrupt", [_interrupt_solver, _interrupt_mesh_export,
                                       _interrupt_level_set_save, _interrupt_plot],
                         ids=lambda f: f.__name__.removeprefix("_interrupt_"))
def test_an_interrupted_run_leaves_no_output_and_no_temporary_file(
    capsys, folder, monkeypatch, interrupt
):
    interrupt(monkeypatch)
    status = main(reconstruct_all(folder))
    err = capsys.readouterr().err
    assert status == 130
    assert err.strip().splitlines()[-1] == "warpspec: interrupted; no output was written"
    assert only_the_scene_is_left(folder), sorted(p.name for p in folder.iterdir())


def test_an_interrupted_run_keeps_the_previous_output(capsys, folder, monkeypatch):
    previous = b"the mesh of an earlier run"
    (folder / "mesh.ply").write_bytes(previous)
    _interrupt_mesh_export(monkeypatch)
    assert main(reconstruct_all(folder)) == 130
    assert (folder / "mesh.ply").read_bytes() == previous
    assert sorted(p.name for p in folder.iterdir()) == ["mesh.ply", "octant.json"]


def test_a_failed_write_is_one_line_and_leaves_nothing(capsys, folder, monkeypatch):
    def write_ply(path, vertices, faces, **kwargs):
        Path(path).write_bytes(b"ply\n")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("warpspec.mesh.write_ply", write_ply)
    status = main(reconstruct_all(folder))
    err = capsys.readouterr().err
    assert status == 1
    assert err.strip().splitlines() == [
        f"warpspec: failed: cannot write {str(folder / 'mesh.ply')!r}: No space left on device"]
    assert only_the_scene_is_left(folder)


def test_a_non_finite_level_set_stops_the_run_naming_the_iteration(capsys, folder, monkeypatch):
    original = ws.Reconstructor.step

    def step(self, **kwargs):
        original(self, **kwargs)
        if self.iteration == 3:
            self.workspace.phi.fill_(float("nan"))

    monkeypatch.setattr(ws.Reconstructor, "step", step)
    status = main(reconstruct_all(folder))
    err = capsys.readouterr().err
    assert status == 1
    assert err.strip().splitlines() == [
        line for line in err.strip().splitlines() if line.startswith("warpspec: failed: ")]
    assert "iteration 3: phi has" in err and "non-finite" in err
    assert only_the_scene_is_left(folder)


def test_a_bug_is_reported_in_one_line_without_a_traceback(capsys, folder, monkeypatch):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr("warpspec.geometry.crop_to_hull", broken)
    monkeypatch.delenv("WARPSPEC_DEBUG", raising=False)
    status = main(["reconstruct", str(folder / "octant.json"), "-o", str(folder / "x.ply"),
                   *FAST, "--crop", "hull"])
    err = capsys.readouterr().err
    assert status == 1
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith(
        "warpspec: internal error: ZeroDivisionError: float division by zero")
    assert only_the_scene_is_left(folder)


def test_suspicious_input_is_a_one_line_warning_and_the_run_goes_on(capsys, folder):
    data = json.loads(OCTANT.read_text())
    data["domain"] = {"min": [-0.1, -0.1, -0.1], "max": [0.95, 1.1, 1.1]}  # (1, 0, 0) outside
    path = folder / "octant.json"
    path.write_text(json.dumps(data))
    status = main(["reconstruct", str(path), "-o", str(folder / "x.ply"), *FAST])
    err = capsys.readouterr().err
    assert status == 0, err
    assert "warpspec: warning: points[0]: [1, 0, 0] lies outside the domain box" in err
    assert all(line.startswith("warpspec: ") for line in err.strip().splitlines())
    assert (folder / "x.ply").exists()


# -- inputs are never modified ----------------------------------------------------------------


def test_reconstruct_modifies_neither_the_dict_nor_the_scene_nor_the_file(folder):
    data = json.loads(OCTANT.read_text())
    kept = copy.deepcopy(data)
    scene = ws.Scene.from_dict(data)
    arrays = {name: getattr(scene, name).copy()
              for name in ("cameras", "spec_camera", "spec_pixel", "points")}
    light = scene.light.vector.copy()
    ws.reconstruct(scene, iterations=3, **OPTIONS)
    assert data == kept
    for name, before in arrays.items():
        after = getattr(scene, name)
        np.testing.assert_array_equal(after, before)
        assert not after.flags.writeable  # nobody can change them behind the scene's back
    np.testing.assert_array_equal(scene.light.vector, light)

    path = folder / "octant.json"
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    mtime = path.stat().st_mtime_ns
    ws.reconstruct(path, iterations=2, **OPTIONS)
    assert main(["reconstruct", str(path), "-o", str(folder / "x.ply"), *FAST, "--quiet"]) == 0
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert path.stat().st_mtime_ns == mtime


def test_user_arrays_given_to_a_scene_are_copied(folder):
    scene = ws.Scene.load(folder / "octant.json")
    cameras = np.array(scene.cameras)
    points = np.array(scene.points)
    pixels = np.array(scene.spec_pixel)
    copy_of = (cameras.copy(), points.copy(), pixels.copy())
    built = ws.Scene(cameras, scene.spec_camera.tolist(), pixels, points, light=scene.light)
    cameras[0, 0, 0] = 1e9  # the caller changes its own arrays afterwards
    points[:] = 0
    ws.reconstruct(built, iterations=2, **OPTIONS)
    np.testing.assert_array_equal(built.cameras, copy_of[0])
    np.testing.assert_array_equal(built.points, copy_of[1])
    np.testing.assert_array_equal(built.spec_pixel, copy_of[2])


# -- determinism ------------------------------------------------------------------------------


def test_cpu_runs_are_bitwise_reproducible():
    scene = ws.Scene.load(OCTANT)

    def run():
        solver = ws.Reconstructor(scene, resolution=20, start="paper", bulge=0.5, device="cpu")
        solver.run(15)
        result = solver.result()
        history = [{k: v for k, v in row.items() if k != "seconds"} for row in result.history]
        return result.phi, result.mesh, history

    phi_a, mesh_a, hist_a = run()
    phi_b, mesh_b, hist_b = run()
    assert phi_a.dtype == np.float32
    assert phi_a.tobytes() == phi_b.tobytes()
    assert mesh_a.vertices.tobytes() == mesh_b.vertices.tobytes()
    np.testing.assert_array_equal(mesh_a.faces, mesh_b.faces)
    assert json.dumps(hist_a) == json.dumps(hist_b)


def test_cli_runs_write_identical_files(capsys, tmp_path):
    outputs = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        mesh, phi = tmp_path / name / "mesh.ply", tmp_path / name / "phi.npz"
        assert main(["reconstruct", str(OCTANT), "-o", str(mesh), *FAST, "--quiet",
                     "--save-phi", str(phi)]) == 0
        with np.load(phi) as saved:
            outputs.append((mesh.read_bytes(), saved["phi"].tobytes()))
    assert outputs[0] == outputs[1]
