"""Benchmark: the paper's octant end to end, from an empty kernel cache (cold) and warm.

Each run is a fresh Python process, timed from outside (wall clock, and the CPU seconds of the
process from ``getrusage``), so interpreter start, imports, kernel compilation or cache loads,
the set-up, the iterations, marching cubes and writing the mesh all count:

- ``cli``: ``warpspec reconstruct examples/scenes/octant.json -o OUT.ply --quiet``
  (plus ``--metrics M.csv --measure-every 0`` to read the final errors: the measures of the
  start and the end, as a run without ``--metrics`` reduces them; and ``--resolution``/
  ``--iterations``/``--device`` when they differ from the defaults);
- ``api``: ``Reconstructor(scene, resolution=64)``, ``.run(300)``, ``.result()``
  and ``.write_mesh`` in a short script, which also reports its own phases.

Cold: ``WARP_CACHE_PATH`` points at a new empty folder (Python's bytecode and the OS file cache
stay warm). Warm: the next processes on that same folder. Rows give the median of the runs.

    python benchmarks/bench_octant.py [--repeats 3] [--cold-repeats 1] [--device cpu]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OCTANT = ROOT / "examples" / "scenes" / "octant.json"

API_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
import warpspec as ws
cfg = json.loads(sys.argv[1])
t1 = time.perf_counter()
solver = ws.Reconstructor(ws.Scene.load(cfg["scene"]), resolution=cfg["resolution"],
                          device=cfg["device"])
t2 = time.perf_counter()
solver.run(cfg["iterations"])
t3 = time.perf_counter()
result = solver.result()
t4 = time.perf_counter()
result.write_mesh(cfg["output"])
t5 = time.perf_counter()
last = result.history[-1]
print("BENCH-JSON " + json.dumps({
    "import_s": t1 - t0, "setup_s": t2 - t1, "run_s": t3 - t2, "result_s": t4 - t3,
    "export_s": t5 - t4, "normal_error": last["normal_error"],
    "point_error": last["point_error"], "misses": last["misses"],
    "faces": int(len(result.faces))}))
"""


def _warpspec_command() -> list[str]:
    script = Path(sys.executable).with_name("warpspec")
    return [str(script)] if script.exists() else [sys.executable, "-m", "warpspec"]


def cli_command(args: argparse.Namespace, output: Path, metrics: Path) -> list[str]:
    """The command line that the ``cli`` rows time."""
    cmd = _warpspec_command() + ["reconstruct", str(OCTANT.relative_to(ROOT)), "-o", str(output),
                                 "--quiet", "--metrics", str(metrics),
                                 "--measure-every", "0"]
    if args.resolution != 64:
        cmd += ["--resolution", str(args.resolution)]
    if args.iterations != 300:
        cmd += ["--iterations", str(args.iterations)]
    if args.device != "cpu":
        cmd += ["--device", args.device]
    return cmd


def _run(cmd: list[str], cache: str | None) -> tuple[float, float, str]:
    """Run one process; return wall seconds, CPU seconds and its standard output."""
    env = os.environ.copy()
    if cache is not None:
        env["WARP_CACHE_PATH"] = cache
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}:\n{proc.stderr}")
    return wall, cpu, proc.stdout


def run_once(runner: str, args: argparse.Namespace, cache: str | None, work: Path) -> dict:
    """One timed end-to-end run of ``runner`` (``cli`` or ``api``) with the given cache."""
    output = work / f"octant-{runner}.ply"
    if runner == "cli":
        metrics = work / "metrics.csv"
        wall, cpu, _ = _run(cli_command(args, output, metrics), cache)
        with open(metrics, newline="") as f:
            last = list(csv.DictReader(f))[-1]
        return {"wall_s": wall, "cpu_s": cpu, "normal_error": float(last["normal_error"]),
                "point_error": float(last["point_error"])}
    cfg = {"scene": str(OCTANT), "resolution": args.resolution,
           "device": args.device, "iterations": args.iterations, "output": str(output)}
    wall, cpu, out = _run([sys.executable, "-c", API_SCRIPT, json.dumps(cfg)], cache)
    line = next(x for x in out.splitlines() if x.startswith("BENCH-JSON "))
    return {"wall_s": wall, "cpu_s": cpu, **json.loads(line[len("BENCH-JSON "):])}


def measure(args: argparse.Namespace) -> list[dict]:
    """All the rows: for each runner, its cold runs then its warm runs on the same cache."""
    rows = []
    work = Path(tempfile.mkdtemp(prefix="warpspec-bench-octant-"))
    try:
        for runner in args.runners:
            runs = {}
            if "cold" in args.modes:
                cache = None
                for _ in range(args.cold_repeats):
                    cache = tempfile.mkdtemp(prefix="cache-", dir=work)
                    runs.setdefault("cold (empty cache)", []).append(
                        run_once(runner, args, cache, work))
                warm_label = "warm (same cache)"
            else:
                cache = args.cache  # None: the environment's WARP_CACHE_PATH as it is
                warm_label = "warm (existing cache)"
            if "warm" in args.modes:
                for _ in range(args.repeats):
                    runs.setdefault(warm_label, []).append(run_once(runner, args, cache, work))
            for label, samples in runs.items():
                row = {"runner": runner, "cache": label, "runs": len(samples),
                       "samples": samples}
                for key in samples[0]:
                    values = [s[key] for s in samples]
                    if all(isinstance(v, int | float) for v in values):
                        row[key] = statistics.median(values)
                row["wall_min_s"] = min(s["wall_s"] for s in samples)
                rows.append(row)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


def tables(rows: list[dict], args: argparse.Namespace) -> str:
    """Markdown tables of :func:`measure`'s rows."""
    lines = [
        "| runner | kernel cache | runs | wall (s), median | wall (s), min | CPU (s) "
        "| normal error | point error (voxel) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['runner']} | {r['cache']} | {r['runs']} | {r['wall_s']:.2f} "
            f"| {r['wall_min_s']:.2f} | {r['cpu_s']:.2f} | {r['normal_error']:.3g} "
            f"| {r['point_error']:.3g} |"
        )
    api = [r for r in rows if r["runner"] == "api"]
    if api:
        lines += [
            "",
            "Phases of the API runs (s, medians, measured inside the process; set-up includes "
            "compiling or loading the kernels on first use):",
            "",
            "| kernel cache | import | set-up | run | ms / iteration (incl. measures) "
            "| result (mesh) | export | process overhead |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in api:
            inside = sum(r[k] for k in ("import_s", "setup_s", "run_s", "result_s", "export_s"))
            lines.append(
                f"| {r['cache']} | {r['import_s']:.2f} | {r['setup_s']:.2f} | {r['run_s']:.2f} "
                f"| {1e3 * r['run_s'] / args.iterations:.1f} | {r['result_s']:.2f} "
                f"| {r['export_s']:.2f} | {r['wall_s'] - inside:.2f} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=64, help="grid resolution")
    parser.add_argument("--iterations", type=int, default=300, help="iterations of the flow")
    parser.add_argument("--repeats", type=int, default=3, help="warm runs per runner (median)")
    parser.add_argument("--cold-repeats", type=int, default=1,
                        help="cold runs per runner, each on a new empty cache (median)")
    parser.add_argument("--modes", nargs="+", choices=("cold", "warm"), default=["cold", "warm"],
                        help="which rows to run; warm alone uses --cache or the environment's")
    parser.add_argument("--runners", nargs="+", choices=("cli", "api"), default=["cli", "api"],
                        help="the command line, the Python API, or both")
    parser.add_argument("--cache", default=None,
                        help="kernel cache for warm-only runs (default: WARP_CACHE_PATH as set)")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0)")
    parser.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)

    rows = measure(args)
    cmd = cli_command(args, Path("OUT.ply"), Path("METRICS.csv"))
    cmd[0] = Path(cmd[0]).name if cmd[0] != sys.executable else "python"
    print(f"Octant end to end ({args.resolution}^3, {args.iterations} iterations, default "
          f"options, device {args.device}); each run a new process. The cli rows time "
          f"`{' '.join(cmd)}`.")
    print()
    print(tables(rows, args))
    if args.json:
        Path(args.json).write_text(json.dumps({"device": args.device, "rows": rows}, indent=1))
    return rows


if __name__ == "__main__":
    main()
