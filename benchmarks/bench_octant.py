"""Benchmark: the paper's octant end to end, per stage, at several grids (cold and warm cache).

Each run is a fresh Python process, timed from outside (wall clock, and the CPU seconds of the
process from ``getrusage``), so interpreter start, imports, kernel compilation or cache loads,
the set-up, the iterations, meshing and writing the mesh all count. Default options: the
iterations follow the schedule of :func:`warpspec.options.default_iterations` unless
``--iterations`` is given.

- ``cli``: ``warpspec reconstruct examples/scenes/octant.json -o OUT.ply --quiet``
  (plus ``--metrics M.csv --measure-every 0`` to read the final errors: the measures of the
  start and the end, as a run without ``--metrics`` reduces them; and ``--resolution``/
  ``--iterations``/``--device`` when they differ from the defaults); the last mesh of each
  grid is then compared with the true sphere by ``warpspec evaluate`` (not timed);
- ``api``: ``Reconstructor(scene, resolution=N)``, ``.run()``, ``.result()`` and
  ``.write_mesh`` in a short script that reports its stages: import, set-up (the constructor:
  grid and device arrays, the start fitted on its ladder of grids, the band), iterations,
  meshing (``result()``) and export, with the process's peak resident memory after each (and
  the memory pool's high-water mark on CUDA).

Cold: ``WARP_CACHE_PATH`` points at a new empty folder (Python's bytecode and the OS file cache
stay warm); cold runs are made at the first grid only (compiling does not depend on it). Warm:
the next processes on that same folder. Rows give the median of the runs.

    python benchmarks/bench_octant.py [--resolutions 64 128 256] [--repeats 3] [--device cpu]
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OCTANT = ROOT / "examples" / "scenes" / "octant.json"
TRUTH = ROOT / "examples" / "scenes" / "octant.ply"
TRUTH_JSON = ROOT / "examples" / "scenes" / "octant.truth.json"

API_SCRIPT = r"""
import json, resource, sys, time
t0 = time.perf_counter()
import warp as wp
import warpspec as ws
cfg = json.loads(sys.argv[1])
t1 = time.perf_counter()

def peak():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB

# the set-up's parts, timed by wrapping the start's build and the ladder's levels (left out
# when those names change: the set-up's total is still measured)
split = {"start_s": 0.0, "levels": []}
try:
    from warpspec.solver import reconstructor as _rec

    _make_start = _rec.make_start

    def make_start(*a, **k):
        strategy = _make_start(*a, **k)
        build = strategy.build

        def timed(scene, workspace):
            s = time.perf_counter()
            out = build(scene, workspace)
            wp.synchronize_device(workspace.device)
            split["start_end"] = time.perf_counter()
            split["start_s"] += split["start_end"] - s
            return out

        strategy.build = timed
        return strategy

    _rec.make_start = make_start
    from warpspec import implicit as _imp

    _level_init = _imp._Level.__init__

    def level_init(self, grid, device, **options):
        split["levels"].append([max(grid.shape) - 1, time.perf_counter()])
        _level_init(self, grid, device, **options)

    _imp._Level.__init__ = level_init
except (ImportError, AttributeError):
    split = None

solver = ws.Reconstructor(ws.Scene.load(cfg["scene"]), resolution=cfg["resolution"],
                          device=cfg["device"])
wp.synchronize_device(solver.device)
t2 = time.perf_counter()
rss = {"setup": peak()}
iterations = solver.default_iterations if cfg["iterations"] is None else cfg["iterations"]
solver.run(iterations)
wp.synchronize_device(solver.device)
t3 = time.perf_counter()
rss["run"] = peak()
result = solver.result()
t4 = time.perf_counter()
rss["mesh"] = peak()
result.write_mesh(cfg["output"])
t5 = time.perf_counter()
rss["export"] = peak()
pool = None
if solver.device.is_cuda:
    try:
        pool = int(wp.get_mempool_used_mem_high(solver.device))
    except Exception:
        pool = None
levels = None
if split and split["levels"]:
    # each level's time: from its start to the next one's (the last: to the end of the start)
    marks = split["levels"]
    ends = [m[1] for m in marks[1:]] + [split.get("start_end", t2)]
    levels = [[res, end - begin] for (res, begin), end in zip(marks, ends)]
last = result.history[-1]
print("BENCH-JSON " + json.dumps({
    "import_s": t1 - t0, "setup_s": t2 - t1, "run_s": t3 - t2, "result_s": t4 - t3,
    "export_s": t5 - t4, "iterations": iterations,
    "start_s": split["start_s"] if split else None, "levels": levels,
    "rss_setup_bytes": rss["setup"], "rss_run_bytes": rss["run"],
    "rss_mesh_bytes": rss["mesh"], "rss_peak_bytes": rss["export"], "pool_high_bytes": pool,
    "normal_error": last["normal_error"],
    "point_error": last["point_error"], "misses": last["misses"],
    "faces": int(len(result.faces))}))
"""


def _warpspec_command() -> list[str]:
    script = Path(sys.executable).with_name("warpspec")
    return [str(script)] if script.exists() else [sys.executable, "-m", "warpspec"]


def cli_command(args: argparse.Namespace, resolution: int, output: Path,
                metrics: Path) -> list[str]:
    """The command line that the ``cli`` rows time."""
    cmd = _warpspec_command() + ["reconstruct", str(OCTANT.relative_to(ROOT)), "-o", str(output),
                                 "--quiet", "--metrics", str(metrics),
                                 "--measure-every", "0"]
    if resolution != 64:
        cmd += ["--resolution", str(resolution)]
    if args.iterations is not None:
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


def run_once(runner: str, args: argparse.Namespace, resolution: int, cache: str | None,
             work: Path) -> dict:
    """One timed end-to-end run of ``runner`` (``cli`` or ``api``) with the given cache."""
    output = work / f"octant-{runner}-{resolution}.ply"
    if runner == "cli":
        metrics = work / "metrics.csv"
        wall, cpu, _ = _run(cli_command(args, resolution, output, metrics), cache)
        with open(metrics, newline="") as f:
            last = list(csv.DictReader(f))[-1]
        return {"wall_s": wall, "cpu_s": cpu, "normal_error": float(last["normal_error"]),
                "point_error": float(last["point_error"]), "iterations": int(last["iteration"])}
    cfg = {"scene": str(OCTANT), "resolution": resolution,
           "device": args.device, "iterations": args.iterations, "output": str(output)}
    wall, cpu, out = _run([sys.executable, "-c", API_SCRIPT, json.dumps(cfg)], cache)
    line = next(x for x in out.splitlines() if x.startswith("BENCH-JSON "))
    return {"wall_s": wall, "cpu_s": cpu, **json.loads(line[len("BENCH-JSON "):])}


def evaluate(mesh: Path, work: Path) -> dict:
    """``warpspec evaluate`` of a mesh against the true octant (its JSON report)."""
    report = work / "evaluate.json"
    cmd = _warpspec_command() + ["evaluate", str(mesh), "--truth", str(TRUTH), "--truth-json",
                                 str(TRUTH_JSON), "--scene", str(OCTANT), "--json", str(report)]
    _run(cmd, None)
    out = json.loads(report.read_text())
    # The truth mesh is an icosphere, faceted to about 1.7e-4: below that it cannot tell two
    # meshes apart. The octant is the unit sphere, so the exact distance is | |v| - 1 |.
    import trimesh

    v = np.asarray(trimesh.load(mesh, process=False).vertices)
    v = v[np.all(v >= 0.0, axis=1)]
    out["exact_mean"] = float(np.mean(np.abs(np.linalg.norm(v, axis=1) - 1.0)))
    return out


def _row(runner: str, resolution: int, label: str, samples: list[dict]) -> dict:
    row = {"runner": runner, "resolution": resolution, "cache": label, "runs": len(samples),
           "samples": samples}
    for key in samples[0]:
        values = [s[key] for s in samples]
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
            row[key] = statistics.median(values)
        elif key == "levels":
            row[key] = samples[len(samples) // 2][key]
    row["wall_min_s"] = min(s["wall_s"] for s in samples)
    return row


def measure(args: argparse.Namespace) -> tuple[list[dict], list[dict]]:
    """The rows (for each grid and runner: its cold runs, then its warm runs on the same
    cache) and the accuracy of each grid's last mesh."""
    rows, accuracy = [], []
    work = Path(tempfile.mkdtemp(prefix="warpspec-bench-octant-"))
    try:
        caches = {}
        for n, resolution in enumerate(args.resolutions):
            last_mesh = None
            for runner in args.runners:
                runs = {}
                if "cold" in args.modes and n == 0:
                    for _ in range(args.cold_repeats):
                        caches[runner] = tempfile.mkdtemp(prefix="cache-", dir=work)
                        runs.setdefault("cold (empty cache)", []).append(
                            run_once(runner, args, resolution, caches[runner], work))
                cache = caches.get(runner, args.cache)  # None: WARP_CACHE_PATH as it is
                warm_label = ("warm (same cache)" if runner in caches
                              else "warm (existing cache)")
                if "warm" in args.modes:
                    repeats = args.repeats if resolution <= 256 else args.large_repeats
                    for _ in range(repeats):
                        runs.setdefault(warm_label, []).append(
                            run_once(runner, args, resolution, cache, work))
                for label, samples in runs.items():
                    rows.append(_row(runner, resolution, label, samples))
                if runs and (last_mesh is None or runner == "cli"):
                    last_mesh = work / f"octant-{runner}-{resolution}.ply"
            if last_mesh is not None and not args.no_evaluate:
                report = evaluate(last_mesh, work)
                accuracy.append({**report, "evaluate_resolution": report["resolution"],
                                 "resolution": resolution})
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows, accuracy


def _gib(value: float | None) -> str:
    return "n/a" if value is None else f"{value / 2**30:.2f}"


def tables(rows: list[dict], accuracy: list[dict], args: argparse.Namespace) -> str:
    """Markdown tables of :func:`measure`'s rows: end to end, accuracy, then per stage."""
    lines = [
        "| grid | runner | kernel cache | iterations | runs | wall (s), median | wall (s), min "
        "| CPU (s) | normal error | point error (voxel) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['resolution']}^3 | {r['runner']} | {r['cache']} | {r['iterations']:.0f} "
            f"| {r['runs']} | {r['wall_s']:.2f} | {r['wall_min_s']:.2f} | {r['cpu_s']:.2f} "
            f"| {r['normal_error']:.3g} | {r['point_error']:.3g} |"
        )
    if accuracy:
        lines += [
            "",
            "Accuracy of each grid's mesh against the true sphere (`warpspec evaluate MESH "
            "--truth examples/scenes/octant.ply --truth-json examples/scenes/octant.truth.json "
            "--scene examples/scenes/octant.json`; world units, the domain is 1.25 wide, and "
            "in voxels h of that grid):",
            "",
            "| grid | h | accuracy mean | accuracy rms | accuracy max | completeness mean "
            "| accuracy mean (h) | normal angle at the specular points, mean (deg) "
            "| exact: mean of abs(abs(v) - 1) over the vertices in the octant |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for a in accuracy:
            # evaluate's h is the domain / its own resolution (64 by default)
            h = a["spacing"] * a["evaluate_resolution"] / a["resolution"]
            acc = a["accuracy"]
            lines.append(
                f"| {a['resolution']}^3 | {h:.4g} | {acc['mean']:.3g} | {acc['rms']:.3g} "
                f"| {acc['max']:.3g} | {a['completeness']['mean']:.3g} "
                f"| {acc['mean'] / h:.3f} | {a['normal_angle_deg']['mean']:.3f} "
                f"| {a.get('exact_mean', float('nan')):.3g} |"
            )
    api = [r for r in rows if r["runner"] == "api"]
    levels = [r for r in api if r.get("levels")]
    if levels:
        lines += [
            "",
            "The start's ladder of grids (API runs, s, the median run; each level from its "
            "start to the next one's, so a level includes the rounds of its fit):",
            "",
            "| grid | kernel cache | levels |",
            "|---|---|---|",
        ]
        for r in levels:
            shown = ", ".join(f"{res}: {sec:.2f}" for res, sec in r["levels"])
            lines.append(f"| {r['resolution']}^3 | {r['cache']} | {shown} |")
    if api:
        cuda = any(r.get("pool_high_bytes") is not None for r in api)
        lines += [
            "",
            "Per stage (API runs, s, medians, measured inside the process; set-up is the "
            "constructor: grid and device arrays, the start fitted coarse to fine, the band; "
            "it includes compiling or loading the kernels on first use; peak memory is the "
            "process's resident high-water mark after each stage" +
            (", and the device memory pool's high-water mark" if cuda else "") + ", in GiB):",
            "",
            "| grid | kernel cache | import | set-up | of which the start | iterations "
            "| ms / iteration | meshing | export | end to end (wall) | set-up share "
            "| peak after set-up | after iterations | after meshing" +
            (" | device pool high |" if cuda else " |"),
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if cuda else ""),
        ]
        for r in api:
            start = r.get("start_s")
            lines.append(
                f"| {r['resolution']}^3 | {r['cache']} | {r['import_s']:.2f} "
                f"| {r['setup_s']:.2f} | {'n/a' if start is None else f'{start:.2f}'} "
                f"| {r['run_s']:.2f} ({r['iterations']:.0f}) "
                f"| {1e3 * r['run_s'] / max(r['iterations'], 1):.1f} | {r['result_s']:.2f} "
                f"| {r['export_s']:.2f} | {r['wall_s']:.2f} "
                f"| {100 * r['setup_s'] / r['wall_s']:.0f}% | {_gib(r['rss_setup_bytes'])} "
                f"| {_gib(r['rss_run_bytes'])} | {_gib(r['rss_mesh_bytes'])}"
                + (f" | {_gib(r.get('pool_high_bytes'))} |" if cuda else " |")
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", "--resolution", nargs="+", type=int, default=[64],
                        help="grid resolutions, one row each (default 64)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="iterations of the flow (default: the schedule for the grid)")
    parser.add_argument("--repeats", type=int, default=3, help="warm runs per runner (median)")
    parser.add_argument("--large-repeats", type=int, default=1,
                        help="warm runs per runner at grids above 256 (minutes each on a CPU)")
    parser.add_argument("--cold-repeats", type=int, default=1,
                        help="cold runs per runner, each on a new empty cache (median), at "
                             "the first resolution")
    parser.add_argument("--modes", nargs="+", choices=("cold", "warm"), default=["cold", "warm"],
                        help="which rows to run; warm alone uses --cache or the environment's")
    parser.add_argument("--runners", nargs="+", choices=("cli", "api"), default=["cli", "api"],
                        help="the command line, the Python API, or both")
    parser.add_argument("--cache", default=None,
                        help="kernel cache for warm-only runs (default: WARP_CACHE_PATH as set)")
    parser.add_argument("--no-evaluate", action="store_true",
                        help="skip the comparison with the true sphere")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0)")
    parser.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)

    rows, accuracy = measure(args)
    cmd = cli_command(args, 64 if len(args.resolutions) > 1 else args.resolutions[0],
                      Path("OUT.ply"), Path("METRICS.csv"))
    cmd[0] = Path(cmd[0]).name if cmd[0] != sys.executable else "python"
    if len(args.resolutions) > 1:
        cmd[cmd.index("--quiet"):cmd.index("--quiet")] = ["--resolution", "N"]
    grids = ", ".join(f"{n}^3" for n in args.resolutions)
    iterations = ("the scheduled iterations" if args.iterations is None
                  else f"{args.iterations} iterations")
    print(f"Octant end to end ({grids}, {iterations}, "
          f"default options, device {args.device}); each run a new process. The cli rows time "
          f"`{' '.join(cmd)}`.")
    print()
    print(tables(rows, accuracy, args))
    if args.json:
        Path(args.json).write_text(json.dumps({"device": args.device, "rows": rows,
                                               "accuracy": accuracy}, indent=1))
    return rows


if __name__ == "__main__":
    main()
