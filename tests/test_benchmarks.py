"""Smoke runs of the benchmark scripts at tiny sizes, and the NumPy peer's agreement check.

The benchmarks' numbers are not asserted here (they are measurements, not tests); these only
prove that every script still runs against the current solver and prints its markdown table.
"""

import importlib.util
import sys
from pathlib import Path

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


def test_bench_octant_prints_its_table(capsys):
    # warm only, on the suite's kernel cache: a cold compile would take a minute
    rows = load("bench_octant").main(["--resolution", "16", "--iterations", "2", "--repeats",
                                      "1", "--modes", "warm"])
    out = capsys.readouterr().out
    assert len(table_rows(out, "cli | warm")) == 1
    assert len(table_rows(out, "api | warm")) == 1
    assert {r["runner"] for r in rows} == {"cli", "api"}
    for r in rows:
        assert r["normal_error"] >= 0.0 and r["point_error"] >= 0.0


def test_run_all_writes_the_markdown(tmp_path, capsys):
    output = tmp_path / "BENCHMARKS.md"
    status = load("run_all").main(["--smoke", "--only", "numpy_step", "--output", str(output)])
    assert status == 0, capsys.readouterr().err
    text = output.read_text()
    assert "## Machine" in text and "| warp |" in text and "| cpu |" in text
    assert "python benchmarks/run_all.py --smoke --only numpy_step" in text
    assert table_rows(text, "octant state")


def test_run_all_checks_the_targets():
    run_all = load("run_all")
    runs = {
        "iteration": {"results": {"rows": [{"size": 128, "numpy_s": 1.0, "iteration_s": 0.1}]}},
        "redistance": {"returncode": 0, "stdout": (
            "| 128^3 | skfmm order 1 | 2.900 | 1.0x | 0.340 | 1.00 | 0.4 |\n"
            "| 128^3 | warpspec cpu band=gradient | 0.250 | 11.6x | 0.070 | 0.21 | 0.1 |\n"
            "| 128^3 | warpspec cpu band=gradient cap=6h | 0.050 | 58.0x | 0.20 | 0.6 | 0.5 |\n")},
        "octant": {"results": {"rows": [
            {"runner": "cli", "cache": "cold (empty cache)", "wall_s": 25.0, "cpu_s": 20.0},
            {"runner": "cli", "cache": "warm (same cache)", "wall_s": 4.0, "cpu_s": 3.0}]}},
        "memory": {"results": {"rows": [{"size": 128, "voxels": 100, "held_bytes": 2500,
                                         "tracker_peak_bytes": 4500}]}},
    }
    verdicts = {t: v for t, _, v in run_all.targets(runs, cuda=False)}
    assert verdicts["iteration at 128^3 >= 5x faster than the NumPy step"] == "met"
    assert verdicts["redistance at 128^3 >= 10x faster than scikit-fmm order 1"] == "met"
    assert verdicts["redistance band max error <= 0.1 h (abs(d) < 3h)"] == "met"
    assert verdicts["octant cli, cold (empty cache): <= 20 s"] == "**not met**"
    assert verdicts["octant cli, warm (same cache): <= 5 s"] == "met"
    assert verdicts["peak device memory at 128^3 <= 40 B/voxel"] == "**not met**"


def test_bench_redistance_smoke_prints_full_and_capped_rows():
    import subprocess

    out = subprocess.run([sys.executable, str(BENCH / "bench_redistance.py"), "--smoke"],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    rows = table_rows(out, "24^3")
    names = [row.split("|")[2].strip() for row in rows]
    assert "skfmm order 1" in names and "skfmm order 1 narrow=6h" in names
    assert "warpspec cpu band=gradient cap=6h" in names
    # the capped distance is as good as the full one within 3 h of the sphere
    err = {row.split("|")[2].strip(): float(row.split("|")[5]) for row in rows}
    assert err["warpspec cpu band=gradient cap=6h"] == err["warpspec cpu band=gradient"] < 0.3
