"""Run every benchmark and write BENCHMARKS.md: the tables, the machine, the command.

Each script runs in its own process (``sys.executable``), one after the other, so that their
timings do not overlap; the peers (the NumPy step, scikit-fmm) are timed in the same process
as warpspec, side by side. ``--sizes`` sets the grids of the iteration benchmark and of the
octant end to end per stage (set-up, iterations, meshing, end to end, peak memory). Above
256 the iteration benchmark runs only on CUDA (its NumPy peer would take minutes a step), and
the octant is run once per runner whatever ``--repeats`` says. The results are checked
against the project's targets, in a table at the top.

Notes written by hand under a section's table, between ``<!-- notes: NAME -->`` and
``<!-- /notes -->`` (NAME as in ``--only``), are kept when the file is written again, under
the same section's new table (or, for a benchmark not run, at the end); everything else in
the file is made afresh.

    python benchmarks/run_all.py [--device cpu] [--repeats N] [--sizes 64 128 256 [512]]
    python benchmarks/run_all.py --smoke          # tiny sizes, seconds; for CI
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

BENCHES = ("numpy_step", "iteration", "redistance", "octant", "start", "memory")
TITLES = {
    "numpy_step": "NumPy peer against warpspec's dense step kernel (agreement)",
    "iteration": "One iteration: warpspec against the NumPy step",
    "redistance": "Reinitialisation: warpspec.redistance against scikit-fmm",
    "octant": "The octant end to end, per stage (cold and warm kernel cache)",
    "start": "Each stage of a reconstruction, on every shape class",
    "memory": "Device memory per voxel",
}
SCRIPTS = {
    "numpy_step": "numpy_step.py",
    "iteration": "bench_iteration.py",
    "redistance": "bench_redistance.py",
    "octant": "bench_octant.py",
    "start": "bench_start.py",
    "memory": "bench_memory.py",
}


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (or what ``platform`` knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _mem_total() -> str:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return "unknown"


def _version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version(module)
    except Exception:
        return "not installed"


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                             capture_output=True, text=True, timeout=10)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def machine_info(device: str) -> dict:
    """Platform, CPU, cores, memory, versions and the Warp device's name."""
    import numpy as np
    import warp as wp

    from warpspec._runtime import resolve_device

    dev = resolve_device(device)
    info = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": cpu_model(),
        "cores": f"{os.cpu_count()} ({len(os.sched_getaffinity(0))} usable by this process)"
        if hasattr(os, "sched_getaffinity") else str(os.cpu_count()),
        "memory": _mem_total(),
        "warp": wp.__version__,
        "numpy": np.__version__,
        "scikit-fmm": _version("scikit-fmm"),
        "device": f"{dev.alias}: {dev.name}",
        "commit": f"{_commit()} (the working tree may hold uncommitted changes)",
    }
    if dev.is_cuda:
        info["device"] += (f", sm_{dev.arch}, {dev.total_memory / 2**30:.1f} GiB, "
                           f"driver {wp.get_cuda_driver_version()}")
    return info


def _supports(script: Path, flag: str) -> bool:
    """Whether a script's ``--help`` lists ``flag``."""
    out = subprocess.run([sys.executable, str(script), "--help"], cwd=ROOT, capture_output=True,
                         text=True)
    return flag in out.stdout


def bench_args(name: str, args: argparse.Namespace, cuda: bool) -> list[str] | None:
    """Command-line arguments for one benchmark script, or None to skip it."""
    dev = ["--device", args.device]
    rep = ["--repeats", str(args.repeats)] if args.repeats else []
    if name == "numpy_step":
        return ["--resolution", "12" if args.smoke else "24"] + dev
    if name == "iteration":
        if args.smoke:
            return ["--sizes", "16", "--repeats", "1", "--iterations", "10"] + dev
        return (["--sizes", *args.sizes] if args.sizes else []) + rep + dev
    if name == "octant":
        if args.smoke:
            return ["--resolutions", "16", "--iterations", "2", "--repeats", "1",
                    "--modes", "warm"] + dev
        sizes = [str(n) for n in _sizes(args.sizes)] if args.sizes else ["64", "128", "256"]
        return ["--resolutions", *sizes] + rep + dev
    if name == "start":
        return (["--smoke"] if args.smoke else rep) + dev
    if name == "memory":
        if args.smoke:
            return ["--sizes", "16", "--iterations", "2"] + dev
        return (["--sizes", "64", "128", "256", "512"] if cuda else []) + dev
    if name == "redistance":
        script = HERE / SCRIPTS[name]
        if args.smoke:
            return ["--smoke"] + dev if _supports(script, "--smoke") else None
        sizes = _sizes(args.sizes or ["256"])
        large = ["--large"] if max(sizes) >= 256 else []
        return large + rep + dev
    raise ValueError(name)


def run_bench(name: str, extra: list[str], json_path: Path | None) -> dict:
    """Run one script; return its command, output, seconds and parsed JSON results."""
    cmd = [sys.executable, str(HERE / SCRIPTS[name]), *extra]
    if json_path is not None:
        cmd += ["--json", str(json_path)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    results = None
    if json_path is not None and json_path.exists():
        results = json.loads(json_path.read_text())
    shown = [Path(sys.executable).name if c == sys.executable else c for c in cmd
             if not (json_path is not None and c in ("--json", str(json_path)))]
    shown[1] = str(Path(shown[1]).relative_to(ROOT))
    return {"name": name, "command": shlex.join(shown), "stdout": proc.stdout.strip(),
            "stderr": proc.stderr.strip(), "returncode": proc.returncode, "seconds": seconds,
            "results": results}


def _sizes(values: list[str]) -> list[int]:
    """Grid sizes from ``--sizes`` (``64 128`` or ``64,128``)."""
    return [int(v) for item in values for v in str(item).split(",") if v]


def _redistance_row(stdout: str, size: int = 128, *, capped: bool = False) -> dict | None:
    """The default-band warpspec row of bench_redistance's table at ``size``^3: the full
    distance, or with ``capped`` the one capped as the solver caps it."""
    for line in stdout.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 6 and cells[0] == f"{size}^3" and cells[1].startswith("warpspec") \
                and "band=gradient" in cells[1] and ("cap=" in cells[1]) == capped:
            try:
                return {"method": cells[1], "seconds": float(cells[2]), "peer": cells[3],
                        "speedup": float(cells[4].rstrip("x")), "band_error": float(cells[5])}
            except ValueError:
                return None
    return None


# The targets, defined once: (limit, unit) by name.
ITERATION_RATIO = 10.0       # one iteration at 128^3 against the NumPy step, at least
REDISTANCE_RATIO = 10.0      # redistance at 128^3 against its scikit-fmm peer, at least
BAND_ERROR_H = 0.1           # redistance's worst error within 3 h of the sphere, at most
OCTANT_WALL_S = {64: 3.0, 128: 3.0, 256: 15.0}  # the octant, warm, by command line, at most
OCTANT_COLD_S = 20.0         # the octant at the first grid from an empty kernel cache, at most
SETUP_SHARE = 0.15           # set-up as a share of an end-to-end run at 128 and 256, at most
PEAK_MEMORY_GIB = 24.0       # the process's peak (plus the device pool's) at 512^3, at most
BYTES_PER_VOXEL = 40.0       # tracked peak device memory, at most


def targets(runs: dict[str, dict], cuda: bool) -> list[tuple[str, str, str]]:
    """The targets against what was measured: (target, measured, verdict)."""
    rows = []

    def verdict(ok: bool | None) -> str:
        return "n/a" if ok is None else ("met" if ok else "**not met**")

    it = (runs.get("iteration") or {}).get("results")
    if it:
        by = {r["size"]: r for r in it["rows"]}
        if 128 in by:
            r = by[128]
            ratio = r["numpy_s"] / r["iteration_s"]
            rows.append((f"iteration at 128^3 >= {ITERATION_RATIO:g}x faster than the NumPy "
                         "step", f"{ratio:.2f}x ({1e3 * r['iteration_s']:.1f} ms vs "
                         f"{1e3 * r['numpy_s']:.0f} ms)", verdict(ratio >= ITERATION_RATIO)))
        if cuda and 256 in by:
            ms = 1e3 * by[256]["iteration_s"]
            rows.append(("GPU: iteration at 256^3 <= 2 ms", f"{ms:.2f} ms", verdict(ms <= 2)))
        if cuda:
            rows.append(("GPU: 512^3 runs", "ran" if 512 in by else "not run",
                         verdict(512 in by)))
    red = runs.get("redistance")
    if red and red.get("returncode") == 0:
        for capped, what in ((False, "full grid"), (True, "capped as the solver caps it")):
            row = _redistance_row(red["stdout"], capped=capped)
            if not row:
                continue
            rows.append((f"redistance at 128^3, {what}, >= {REDISTANCE_RATIO:g}x faster than "
                         f"{row['peer']}", f"{row['speedup']:.1f}x ({row['method']}, "
                         f"{row['seconds']:.3f} s)", verdict(row["speedup"] >= REDISTANCE_RATIO)))
            rows.append((f"redistance at 128^3, {what}, band max error <= {BAND_ERROR_H:g} h "
                         "(abs(d) < 3h)", f"{row['band_error']:.3f} h",
                         verdict(row["band_error"] <= BAND_ERROR_H)))
    octant = (runs.get("octant") or {}).get("results")
    if octant:
        rows += _octant_targets(octant, verdict)
    mem = (runs.get("memory") or {}).get("results")
    if mem:
        for r in mem["rows"]:
            peak = r["tracker_peak_bytes"] or r["held_bytes"]
            per = peak / r["voxels"]
            if "pool_high_bytes" in r:
                per = max(per, r["pool_high_bytes"] / r["voxels"])
            rows.append((f"peak device memory at {r['size']}^3 <= {BYTES_PER_VOXEL:g} B/voxel",
                         f"{per:.1f} B/voxel", verdict(per <= BYTES_PER_VOXEL)))
    return rows


def _octant_targets(octant: dict, verdict) -> list[tuple[str, str, str]]:
    """The octant's targets: wall time, accuracy, set-up share and memory by grid."""
    rows = []
    cli = {r["resolution"]: r for r in octant["rows"]
           if r["runner"] == "cli" and r["cache"].startswith("warm")}
    for r in octant["rows"]:
        if r["runner"] == "cli" and r["cache"].startswith("cold"):
            rows.append((f"octant cli at {r['resolution']}^3, cold (empty cache): <= "
                         f"{OCTANT_COLD_S:g} s", f"{r['wall_s']:.2f} s wall, "
                         f"{r['cpu_s']:.2f} s CPU", verdict(r["wall_s"] <= OCTANT_COLD_S)))
    for n, limit in OCTANT_WALL_S.items():
        if n in cli:
            r = cli[n]
            rows.append((f"octant cli at {n}^3, warm: <= {limit:g} s",
                         f"{r['wall_s']:.2f} s wall, {r['cpu_s']:.2f} s CPU",
                         verdict(r["wall_s"] <= limit)))
    # against the exact sphere: the truth mesh is faceted to about 1.7e-4, coarser than both
    acc = {a["resolution"]: a["exact_mean"] for a in octant.get("accuracy") or []
           if "exact_mean" in a}
    if 128 in acc and 256 in acc:
        rows.append(("octant accuracy at 256^3 (mean distance to the exact sphere, world "
                     "units) <= at 128^3",
                     f"{acc[256]:.3g} vs {acc[128]:.3g}", verdict(acc[256] <= acc[128])))
    api = {r["resolution"]: r for r in octant["rows"]
           if r["runner"] == "api" and r["cache"].startswith("warm")}
    for n in (128, 256):
        if n in api:
            share = api[n]["setup_s"] / api[n]["wall_s"]
            rows.append((f"set-up at {n}^3 <= {100 * SETUP_SHARE:.0f}% of the end-to-end run",
                         f"{100 * share:.1f}% ({api[n]['setup_s']:.2f} s of "
                         f"{api[n]['wall_s']:.2f} s)", verdict(share <= SETUP_SHARE)))
    if 512 in api:
        r = api[512]
        peak = r["rss_peak_bytes"] + (r.get("pool_high_bytes") or 0)
        rows.append((f"octant at 512^3 (set-up, iterations, meshing) within "
                     f"{PEAK_MEMORY_GIB:g} GiB", f"{peak / 2**30:.2f} GiB peak, "
                     f"{r['wall_s']:.1f} s end to end", verdict(peak <= PEAK_MEMORY_GIB * 2**30)))
    return rows


NOTES = re.compile(r"^<!-- notes: (\w+) -->\n.*?^<!-- /notes -->$", re.M | re.S)


def kept_notes(text: str) -> dict[str, str]:
    """The hand-written notes of a BENCHMARKS.md, markers included, by benchmark name."""
    return {m.group(1): m.group(0) for m in NOTES.finditer(text) if m.group(1) in BENCHES}


def render(runs: dict[str, dict], info: dict, command: str, args: argparse.Namespace,
           cuda: bool, started: str, load: tuple[tuple, tuple], steal: str | None = None,
           notes: dict[str, str] | None = None) -> str:
    """The text of BENCHMARKS.md, with ``notes`` (from :func:`kept_notes`) under their tables."""
    notes = notes or {}
    out = ["# warpspec benchmarks", ""]
    if args.smoke:
        out += ["**Smoke run** (tiny sizes, for CI): the numbers below mean nothing.", ""]
    out += [
        f"Made by `{command}` on {started} (run from the repository root). Each script ran "
        "in its own process; its own command is given with its table. The machine is "
        "shared and timings are noisy: compare the ratios measured side by side in one "
        "process, not absolute times across runs.",
        "",
        "## Machine",
        "",
        "| | |",
        "|---|---|",
    ]
    out += [f"| {k} | {v} |" for k, v in info.items()]
    out += [f"| load average (1, 5, 15 min) | {_load(load[0])} at the start, {_load(load[1])} "
            "at the end |"]
    if steal is not None:
        out += [f"| stolen by the hypervisor during the run | {steal} |"]
    out += [""]
    rows = targets(runs, cuda)
    if rows:
        out += ["## Targets", "", "| target | measured | |", "|---|---|---|"]
        out += [f"| {t} | {m} | {v} |" for t, m, v in rows]
        out.append("")
    for name in BENCHES:
        if name not in runs:
            continue
        run = runs[name]
        out += [f"## {TITLES[name]}", ""]
        if run.get("skipped"):
            out += [f"Skipped: {run['skipped']}.", ""]
            continue
        out += [f"`{run['command']}` ({run['seconds']:.0f} s)", ""]
        if run["returncode"] != 0:
            tail = "\n".join(run["stderr"].splitlines()[-15:])
            out += [f"**Failed** with exit status {run['returncode']}:", "", "```", tail, "```",
                    ""]
        if run["stdout"]:
            out += [run["stdout"], ""]
        if name in notes:
            out += [notes[name], ""]
    orphans = [n for n in BENCHES if n in notes and not (n in runs and "skipped" not in runs[n])]
    if orphans:
        out += ["## Notes of benchmarks not run this time", ""]
        out += [line for n in orphans for line in (notes[n], "")]
    return "\n".join(out).rstrip() + "\n"


def _load(values: tuple) -> str:
    return ", ".join(f"{v:.2f}" for v in values)


def _cpu_ticks() -> list[int] | None:
    """The machine's CPU time counters from /proc/stat (user ... steal), or None."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
    except OSError:
        return None
    return [int(v) for v in fields[1:9]] if fields and fields[0] == "cpu" else None


def _steal(start: list[int] | None, end: list[int] | None) -> str | None:
    """Share of CPU time the hypervisor took from this virtual machine between two readings."""
    if start is None or end is None:
        return None
    delta = [b - a for a, b in zip(start, end, strict=True)]
    total = sum(delta)
    return f"{100.0 * delta[7] / total:.1f}% of all CPU time" if total > 0 else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed runs per row, passed to each script (default: theirs)")
    parser.add_argument("--sizes", nargs="+", default=None,
                        help="grids of the iteration benchmark (default 64 128 256, and 512 "
                             "on CUDA); redistance gets --large when 256 is among them")
    parser.add_argument("--only", nargs="+", choices=BENCHES, default=None,
                        help="run only these benchmarks")
    parser.add_argument("--skip", nargs="+", choices=BENCHES, default=[],
                        help="leave these benchmarks out")
    parser.add_argument("--smoke", action="store_true",
                        help="everything at a tiny size, in seconds (CI); writes "
                             "build/BENCHMARKS.smoke.md unless --output is given")
    parser.add_argument("--output", default=None,
                        help="markdown file to write (default BENCHMARKS.md at the root)")
    args = parser.parse_args(argv)

    started = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    load_start = os.getloadavg()
    ticks_start = _cpu_ticks()
    command = shlex.join(["python", "benchmarks/run_all.py", *(argv if argv is not None
                                                                else sys.argv[1:])])
    info = machine_info(args.device)
    cuda = info["device"].startswith("cuda")
    if args.output is None:
        args.output = str(ROOT / ("build/BENCHMARKS.smoke.md" if args.smoke else "BENCHMARKS.md"))
    names = [n for n in (args.only or BENCHES) if n not in args.skip]
    runs: dict[str, dict] = {}
    failed = []
    with tempfile.TemporaryDirectory(prefix="warpspec-bench-") as tmp:
        for name in names:
            if not (HERE / SCRIPTS[name]).exists():
                runs[name] = {"skipped": f"benchmarks/{SCRIPTS[name]} is not there"}
                continue
            extra = bench_args(name, args, cuda)
            if extra is None:
                runs[name] = {"skipped": f"benchmarks/{SCRIPTS[name]} has no --smoke mode"}
                print(f"[run_all] {name}: skipped ({runs[name]['skipped']})", flush=True)
                continue
            print(f"[run_all] {name}: {SCRIPTS[name]} {shlex.join(extra)}", flush=True)
            wants_json = name in ("iteration", "octant", "memory")
            run = run_bench(name, extra, Path(tmp) / f"{name}.json" if wants_json else None)
            runs[name] = run
            print(run["stdout"], flush=True)
            if run["returncode"] != 0:
                failed.append(name)
                print(run["stderr"], file=sys.stderr, flush=True)
            print(f"[run_all] {name}: {run['seconds']:.0f} s", flush=True)
    output = Path(args.output)
    notes = kept_notes(output.read_text()) if output.is_file() else {}
    text = render(runs, info, command, args, cuda, started, (load_start, os.getloadavg()),
                  _steal(ticks_start, _cpu_ticks()), notes)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text)
    print(f"[run_all] wrote {output}" + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
