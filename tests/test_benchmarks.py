"""Smoke runs of the benchmark scripts at tiny sizes, and the NumPy peer's agreement check.

The benchmarks' numbers are not asserted here (they are measurements, not tests); these only
prove that every script still runs against the current solver and prints its markdown table.
"""

import importlib.util
import re
import sys
from pathlib import Path

import pytest

from warpspec.solver import FULL_REINIT_EVERY

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def load(name: str):
    """Import a script from benchmarks/ (not a package) by its file name."""
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def table_rows(text: str, first_cell: str) -> list[str]:
    """Markdown table rows of ``text`` whose first cell starts with ``first_cell``."""
    lines = text.splitlines()
    assert any(line.startswith("|---") for line in lines), text
    return [line for line in lines if line.startswith(f"| {first_cell}")]


def test_numpy_step_matches_dense_warp_kernel_at_24(device):
    cases = load("numpy_step").verify(24, device=device.alias)
    assert len(cases) == 2
    for case in cases:
        assert case["owned"] > 0
        assert case["max_change"] > 0.0
        assert case["rel_phi"] <= 1e-5, case
        assert case["rel_change"] <= 1e-3, case


def test_numpy_step_is_the_identity_without_terms():
    import numpy as np

    ns = load("numpy_step")
    rng = np.random.default_rng(1)
    phi = rng.standard_normal((6, 7, 8)).astype(np.float32)
    owner = np.full(phi.shape, 2**30, dtype=np.int32)
    out = ns.flow_step(phi, owner, np.zeros((1, 3), np.float32), np.zeros_like(phi),
                       spacing=0.1, dt=1e-3, normal_weight=0.0)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, phi)


def test_bench_iteration_prints_its_tables(device, capsys):
    rows = load("bench_iteration").main(
        ["--sizes", "16", "--repeats", "1", "--iterations", "10", "--device", device.alias])
    out = capsys.readouterr().out
    assert len(table_rows(out, "16^3")) == 2  # the comparison and the split
    # the timed block is rounded up to a whole cycle of band-only and full reinitialisations
    assert rows[0]["iterations_timed"] == 10 * FULL_REINIT_EVERY
    assert rows[0]["numpy_s"] > 0 and rows[0]["iteration_s"] > 0 and rows[0]["kernel_s"] > 0


def test_bench_memory_prints_its_table(device, capsys):
    rows = load("bench_memory").main(["--sizes", "16", "--iterations", "2",
                                      "--device", device.alias])
    out = capsys.readouterr().out
    assert len(table_rows(out, "16^3")) == 1
    assert table_rows(out, "`solver.workspace.phi`")
    # at least phi and its ping-pong twin, 4 bytes a voxel each
    assert rows[0]["held_bytes"] >= 8 * rows[0]["voxels"]
    assert rows[0]["tracker_peak_bytes"] >= rows[0]["held_bytes"] * 0.9


def test_bench_memory_reads_the_trackers_peak():
    report = ("Allocation Tracking Report\n  Peak usage:\n    cpu              2.00 MB\n"
              "    cuda:0           512.00 KB\n  Live allocations:\n    cpu    1 (1.00 MB)\n")
    parse = load("bench_memory").parse_peak
    assert parse(report, "cpu") == 2 * 2**20
    assert parse(report, "cuda:0") == 512 * 2**10
    assert parse(report, "cuda:1") is None
    assert parse("nothing", "cpu") is None


def test_bench_octant_prints_its_tables(capsys):
    # warm only, on the suite's kernel cache: a cold compile would take a minute
    rows = load("bench_octant").main(["--resolutions", "16", "24", "--iterations", "2",
                                      "--repeats", "1", "--modes", "warm"])
    out = capsys.readouterr().out
    for n in (16, 24):
        assert len(table_rows(out, f"{n}^3 | cli | warm")) == 1
        assert len(table_rows(out, f"{n}^3 | api | warm")) == 1
        # the accuracy against the true sphere, and the stages of the API run
        assert len(table_rows(out, f"{n}^3 | ")) == 4
    assert {(r["runner"], r["resolution"]) for r in rows} == {
        (runner, n) for runner in ("cli", "api") for n in (16, 24)}
    for r in rows:
        assert r["iterations"] == 2
        assert r["normal_error"] >= 0.0 and r["point_error"] >= 0.0
    for r in (r for r in rows if r["runner"] == "api"):
        # the stages lie inside the process's wall time, the start inside the set-up
        inside = r["import_s"] + r["setup_s"] + r["run_s"] + r["result_s"] + r["export_s"]
        assert 0.0 < inside < r["wall_s"]
        assert 0.0 < r["start_s"] <= r["setup_s"]
        # the peak resident memory never falls, and holds at least the grid's phi
        assert 0 < r["rss_setup_bytes"] <= r["rss_run_bytes"] <= r["rss_mesh_bytes"]
        assert r["rss_setup_bytes"] >= 4 * (r["resolution"] + 1) ** 3


def test_bench_octant_scheduled_iterations_and_accuracy(capsys):
    # without --iterations the command line and the API run the schedule for the grid
    from warpspec.options import default_iterations

    rows = load("bench_octant").main(["--resolutions", "16", "--repeats", "1",
                                      "--modes", "warm", "--json", "/dev/null"])
    out = capsys.readouterr().out
    assert "--iterations" not in out
    assert {r["iterations"] for r in rows} == {default_iterations(16)}
    acc = [line.split("|") for line in table_rows(out, "16^3 | 0.078")]
    assert len(acc) == 1  # h: the 1.25 wide domain over 16 cells
    # a reconstruction of the sphere within a tenth of a voxel on average
    assert float(acc[0][3]) < 0.1 * 1.25 / 16


def test_run_all_writes_the_markdown(tmp_path, capsys):
    output = tmp_path / "BENCHMARKS.md"
    status = load("run_all").main(["--smoke", "--only", "numpy_step", "--output", str(output)])
    assert status == 0, capsys.readouterr().err
    text = output.read_text()
    assert "## Machine" in text and "| warp |" in text and "| cpu |" in text
    assert "python benchmarks/run_all.py --smoke --only numpy_step" in text
    assert table_rows(text, "octant state")


def test_run_all_keeps_the_notes_written_under_a_table(tmp_path, capsys):
    output = tmp_path / "BENCHMARKS.md"
    step = "<!-- notes: numpy_step -->\nThe step's note.\n<!-- /notes -->"
    start = "<!-- notes: start -->\nA note on the start,\nover two lines.\n<!-- /notes -->"
    output.write_text(f"# old\n\n| old | table |\n\n{step}\n\n## Other\n\n{start}\n")
    status = load("run_all").main(["--smoke", "--only", "numpy_step", "--output", str(output)])
    assert status == 0, capsys.readouterr().err
    text = output.read_text()
    assert "| old | table |" not in text and "# old" not in text
    assert text.count(step) == 1 and text.count(start) == 1
    # under its own table; the note of a benchmark not run is kept at the end
    assert text.index(table_rows(text, "octant state")[-1]) < text.index(step)
    assert text.index("## Notes of benchmarks not run this time") < text.index(start)


def test_run_all_checks_the_targets():
    run_all = load("run_all")
    gib = 2**30
    runs = {
        "iteration": {"results": {"rows": [{"size": 128, "numpy_s": 1.0, "iteration_s": 0.11}]}},
        "redistance": {"returncode": 0, "stdout": (
            "| 128^3 | skfmm order 1 | 2.900 | skfmm order 1 | 1.0x | 0.340 | 1.00 | 0.4 |\n"
            "| 128^3 | warpspec cpu band=gradient | 0.250 | skfmm order 1 | 11.6x | 0.070 "
            "| 0.21 | 0.1 |\n"
            "| 128^3 | warpspec cpu band=gradient cap=8h | 0.150 | skfmm order 1 narrow=8h "
            "| 6.0x | 0.20 | 0.6 | 0.5 |\n")},
        "octant": {"results": {"rows": [
            {"runner": "cli", "resolution": 64, "cache": "cold (empty cache)", "wall_s": 25.0,
             "cpu_s": 20.0},
            {"runner": "cli", "resolution": 64, "cache": "warm (same cache)", "wall_s": 3.1,
             "cpu_s": 3.0},
            {"runner": "cli", "resolution": 128, "cache": "warm (same cache)", "wall_s": 2.9,
             "cpu_s": 3.0},
            {"runner": "cli", "resolution": 256, "cache": "warm (same cache)", "wall_s": 15.5,
             "cpu_s": 16.0},
            {"runner": "api", "resolution": 128, "cache": "warm (same cache)", "wall_s": 3.0,
             "setup_s": 0.44},
            {"runner": "api", "resolution": 256, "cache": "warm (same cache)", "wall_s": 15.0,
             "setup_s": 2.4},
            {"runner": "api", "resolution": 512, "cache": "warm (same cache)", "wall_s": 90.0,
             "setup_s": 9.0, "rss_peak_bytes": 20 * gib, "pool_high_bytes": 5 * gib}],
            "accuracy": [{"resolution": 128, "accuracy": {"mean": 2e-4}, "exact_mean": 2e-5},
                         {"resolution": 256, "accuracy": {"mean": 2e-4}, "exact_mean": 1e-5}]}},
        "memory": {"results": {"rows": [{"size": 128, "voxels": 100, "held_bytes": 2500,
                                         "tracker_peak_bytes": 4500}]}},
    }
    verdicts = {t: v for t, _, v in run_all.targets(runs, cuda=False)}
    assert verdicts == {
        "iteration at 128^3 >= 10x faster than the NumPy step": "**not met**",  # 9.1x
        "redistance at 128^3, full grid, >= 10x faster than skfmm order 1": "met",
        "redistance at 128^3, full grid, band max error <= 0.1 h (abs(d) < 3h)": "met",
        "redistance at 128^3, capped as the solver caps it, >= 10x faster than skfmm order 1 "
        "narrow=8h": "**not met**",
        "redistance at 128^3, capped as the solver caps it, band max error <= 0.1 h "
        "(abs(d) < 3h)": "**not met**",
        "octant cli at 64^3, cold (empty cache): <= 20 s": "**not met**",
        "octant cli at 64^3, warm: <= 3 s": "**not met**",
        "octant cli at 128^3, warm: <= 3 s": "met",
        "octant cli at 256^3, warm: <= 15 s": "**not met**",
        "octant accuracy at 256^3 (mean distance to the exact sphere, world units) <= at "
        "128^3": "met",
        "set-up at 128^3 <= 15% of the end-to-end run": "met",  # 14.7%
        "set-up at 256^3 <= 15% of the end-to-end run": "**not met**",  # 16%
        "octant at 512^3 (set-up, iterations, meshing) within 24 GiB": "**not met**",  # 25
        "peak device memory at 128^3 <= 40 B/voxel": "**not met**",
    }


def test_bench_redistance_smoke_prints_full_and_capped_rows():
    import subprocess

    out = subprocess.run([sys.executable, str(BENCH / "bench_redistance.py"), "--smoke"],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    rows = [[c.strip() for c in row.split("|")[1:-1]] for row in table_rows(out, "24^3")]
    by = {row[1]: row for row in rows}
    # the cap is the solver's: the narrow band's 4 voxels and the 4 beyond
    assert set(by) == {"skfmm order 1", "skfmm order 2", "warpspec cpu band=gradient",
                       "warpspec cpu band=axis", "skfmm order 1 narrow=8h",
                       "warpspec cpu band=gradient cap=8h"}
    # each warpspec row against its fair peer
    assert by["warpspec cpu band=gradient"][3] == "skfmm order 1"
    assert by["warpspec cpu band=gradient cap=8h"][3] == "skfmm order 1 narrow=8h"
    assert by["skfmm order 1"][3:5] == ["skfmm order 1", "1.0x"]
    # the capped distance is as good as the full one within 3 h of the sphere
    err = {name: float(row[5]) for name, row in by.items()}
    assert err["warpspec cpu band=gradient cap=8h"] == err["warpspec cpu band=gradient"] < 0.3


def test_progress_shows_the_stages_on_a_terminal(capsys):
    from warpspec.cli import _Progress

    quiet = _Progress(enabled=False)
    quiet.stage("set-up", "the start")
    quiet.done("set-up")
    quiet.iterations(10)
    assert quiet.bar is None
    assert capsys.readouterr().err == ""
    shown = _Progress(enabled=True)
    shown.stage("set-up", "the start")
    shown.done("set-up")
    shown.stage("meshing")
    shown.done("meshing")
    shown.done("meshing")  # once only
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "warpspec: set-up: the start"
    assert re.fullmatch(r"warpspec: set-up: done in \d+\.\d s", lines[1])
    assert lines[2] == "warpspec: meshing ..."
    assert re.fullmatch(r"warpspec: meshing: done in \d+\.\d s", lines[3])
    assert len(lines) == 4


def test_progress_names_the_starts_ladder():
    from warpspec.cli import _setup_detail

    assert "grids 16 ... 32 ... 64 ... 128 ... 256 ... 512 where" in _setup_detail(
        "implicit", 512, None)
    assert "grids 16 ... 32 ... 64 where" in _setup_detail("implicit", None, None)  # default
    assert "grids 16 ... 32 ... 48 where" in _setup_detail("implicit", 48, None)
    assert _setup_detail("paper", 100, None) == "the paper start on a 100-cell grid"
    assert _setup_detail("implicit", None, Path("a.npz")) == "the level set saved in a.npz"


@pytest.mark.parametrize("quiet", [False, True])
def test_reconstruct_shows_its_stages_on_a_terminal(tmp_path, capsys, monkeypatch, quiet):
    from warpspec.cli import main

    root = BENCH.parent
    monkeypatch.chdir(root)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    status = main(["reconstruct", "examples/scenes/octant.json", "-o", str(tmp_path / "o.ply"),
                   "--resolution", "24", "--iterations", "3"] + (["--quiet"] if quiet else []))
    assert status == 0
    err = capsys.readouterr().err
    stages = [line for line in err.splitlines() if re.match(r"warpspec: (set-up|meshing)", line)]
    if quiet:
        assert stages == []
        return
    assert len(stages) == 4, err
    assert stages[0].startswith("warpspec: set-up: the implicit start") and "16 ... 24" in err
    assert stages[1].startswith("warpspec: set-up: done in ")
    assert stages[2].startswith("warpspec: meshing: ")
    assert stages[3].startswith("warpspec: meshing: done in ")
    assert err.index(stages[3]) < err.index("warpspec: wrote ")


def test_bench_start_smoke_times_the_stages_that_ran():
    import subprocess

    out = subprocess.run([sys.executable, str(BENCH / "bench_start.py"), "--smoke"],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    header = next(line for line in out.splitlines() if line.startswith("| scene |"))
    columns = [c.strip() for c in header.split("|")[1:-1]]
    rows = {r[0]: dict(zip(columns, r, strict=True)) for r in
            ([c.strip() for c in line.split("|")[1:-1]] for line in out.splitlines()
             if line.startswith("| octant") or line.startswith("| torus"))}
    # the octant is a quadric: no torus, no grid fit; the torus is found as a torus
    assert rows["octant"]["torus"] == "-" and rows["octant"]["grid fit"] == "-"
    assert rows["torus"]["torus"] != "-" and rows["torus"]["grid fit"] == "-"
    for row in rows.values():
        stages = [float(v) for k, v in row.items() if k not in ("scene", "total") and v != "-"]
        assert abs(sum(stages) - float(row["total"])) <= 0.01 * len(stages) + 0.01
