"""End-to-end runs of the paper's experiments, small: the pipeline runs and the error is bounded.

Coarse grids and few iterations keep this quick on one CPU core; the bounds are loose enough
for that, and tight enough that a solver that drifts, flips a normal or loses the surface
fails them (on these grids the runs land at 0.002-0.04 voxel and 0.3-1.9 degrees).
"""

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name):
    """Import an example script as a module (the examples import ``experiments`` by name)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    return importlib.import_module(name)


experiments = _load("experiments")


def run(label, resolution, iterations, **options):
    return experiments.run_setup(label, resolution=resolution, iterations=iterations,
                                 device="cpu", measure_every=10, samples=4000,
                                 score_start=False, **options)


# scene label, resolution, iterations, bound on the mean truth-to-mesh distance (voxels),
# bound on the mean normal angle at the true specular points (degrees)
CASES = [
    ("octant", 32, 60, 0.2, 4.0),
    ("octant-noise", 32, 60, 0.25, 4.0),
    ("ellipsoid-cap", 32, 60, 0.25, 5.0),
    ("car-window", 40, 60, 0.2, 4.0),
    ("wine-bottle", 32, 60, 0.2, 5.0),
]


@pytest.mark.parametrize(("label", "resolution", "iterations", "distance", "angle"), CASES,
                         ids=[c[0] for c in CASES])
def test_scene_reconstructs_within_bounds(label, resolution, iterations, distance, angle):
    exp = run(label, resolution, iterations)
    last, first = exp.result.history[-1], exp.result.history[0]
    assert last["iteration"] == iterations
    # Every ray meets the surface, and the constraints hold where the rays meet it.
    assert last["misses"] == 0
    assert last["normal_error"] < 2e-3
    assert last["point_error"] < 0.5
    assert np.isfinite(last["energy_total"])
    # The flow keeps the normal constraints: at most a small rise over a good start.
    assert last["normal_error"] <= max(3.0 * first["normal_error"], 5e-4)
    # The surface is on the truth inside the constraints' hull, both ways.
    assert exp.completeness < distance
    assert exp.accuracy < distance
    assert exp.evaluation.completeness.count > 1000
    assert exp.angle < angle
    # The depth along each ray is right: the hits lie near the true specular points.
    hits = exp.result.hits[exp.synthetic.inliers]
    points = exp.synthetic.truth_points[exp.synthetic.inliers]
    assert np.linalg.norm(hits - points, axis=1).max() < 1.0 * exp.spacing


def test_paper_start_descends_the_normal_energy():
    """From the paper's start (plane and bend, no fit) the flow must align the normals.

    It reaches a local minimum about one voxel off on this grid (docs/RESULTS.md), so only
    the descent and a loose distance bound are checked.
    """
    exp = run("octant-paper", 32, 100)
    first, last = exp.result.history[0], exp.result.history[-1]
    assert first["normal_error"] > 0.05  # the bent plane is far from the sphere's normals
    assert last["normal_error"] < first["normal_error"] / 20
    assert last["energy_normal"] < first["energy_normal"] / 10
    assert last["misses"] == 0
    assert exp.completeness < 3.0


def test_table_row_reports_every_figure():
    exp = run("wine-bottle", 24, 10)
    row = experiments.table_row(exp)
    cells = [c.strip() for c in row.strip("|").split("|")]
    header = [c.strip() for c in experiments.TABLE_HEADER.splitlines()[0].strip("|").split("|")]
    assert len(cells) == len(header)
    assert cells[0] == "wine-bottle" and cells[1] == "11 normals, 4 points"
    assert cells[2] == "24" and cells[3] == "10"
    assert float(cells[5]) == pytest.approx(exp.completeness, abs=1e-3)
    diag = experiments.diagnostics(exp)
    assert set(diag) >= {"hit_offset", "grad_angle", "vertex_angle"}
    assert all(np.isfinite(v) for v in diag.values())


def test_examples_write_their_figures(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    octant = _load("sphere_octant")
    assert octant.main(["--resolution", "16", "--iterations", "5", "--noise", "0",
                        "--out-dir", str(tmp_path)]) == 0
    car = _load("car_window")
    assert car.main(["--resolution", "16", "--iterations", "5",
                     "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for name in ("octant_fig4.png", "octant_fig5.png", "car_window_fig4.png",
                 "car_window_fig5.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    for row in ("| octant-paper |", "| octant |", "| car-window-paper |", "| car-window |"):
        assert row in out
    assert "completeness (truth to mesh)" in out


def _row(scene, seed, variant, score, **extra):
    return {"scene": scene, "seed": seed, "variant": variant, "closed": scene == "sphere",
            "euler_expected": 2, "euler": 2, "watertight": True, "completeness": score,
            "accuracy": score, **extra}


def test_any_shape_summary_takes_each_variant_worst_excess_per_scene():
    any_shape = _load("any_shape")
    rows = [_row("sphere", 0, "clean", 0.1), _row("sphere", 1, "clean", 0.3, euler=0),
            _row("sphere", 0, "outliers 0.1", 0.1, excess=0.02),
            _row("sphere", 1, "outliers 0.1", 0.5, excess=0.2),
            _row("patch", 0, "clean", 0.2, requested=30),
            _row("patch", 0, "clean", 0.4, requested=60),
            {"scene": "patch", "seed": 0, "variant": "outliers 0.1", "requested": 60,
             "error": "no surface"}]
    lines = any_shape.summary(rows)
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]
    assert cells[0] == ["sphere", "2", "0.200 / 0.300", "0.200 / 0.300", "1 of 2",
                        "+0.200 (1 over)"]
    assert cells[1][:5] == ["patch, 30 highlights", "1", "0.200 / 0.200", "0.200 / 0.200",
                            "open"]
    assert cells[2][0] == "patch, 60 highlights" and cells[2][-1] == "- (1 failed)"


def test_any_shape_scores_a_variant_against_its_clean_scene(capsys, tmp_path):
    any_shape = _load("any_shape")
    out = tmp_path / "rows.json"
    assert any_shape.main(["--scene", "octant", "--outliers", "0.25", "--resolution", "24",
                           "--iterations", "20", "--samples", "2000", "--summary",
                           "--json", str(out)]) == 0
    rows = {r["variant"]: r for r in json.loads(out.read_text())}
    clean, false = rows["clean"], rows["outliers 0.25"]
    score = 0.5 * (false["completeness"] + false["accuracy"])
    assert false["excess"] == pytest.approx(score - 0.5 * (clean["completeness"]
                                                           + clean["accuracy"]))
    assert 0.0 <= false["vs_clean"] < 0.5
    printed = capsys.readouterr().out
    assert "| octant | 1 |" in printed
    assert any_shape.main(["--summary-of", str(out)]) == 0
    assert "| octant | 1 |" in capsys.readouterr().out
