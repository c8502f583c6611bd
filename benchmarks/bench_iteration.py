"""Benchmark: one solver iteration against one NumPy step of the same PDE.

For each grid (the octant scene at ``resolution=N``, default options, so that the rays
hit the surface and the constraints own nodes), in one process and interleaved, repeated
``--repeats`` times (medians reported):

- NumPy: one explicit float32 step of the flow (``numpy_step.flow_step``, the peer);
- kernel: warpspec's dense fused flow-step kernel alone (``launch_flow_step``) on the same state;
- iteration: ``Reconstructor.step()`` as the solver runs it (ray intersection, constraint
  normals, flow step, and the reinitialisation every ``reinit_every`` steps, amortised): a block
  of a multiple of ``reinit_every * FULL_REINIT_EVERY`` steps (a whole cycle of band-only and
  full reinitialisations), divided by its length.

A second table splits the iteration into its parts and gives the cost of ``measures()``, which
``Reconstructor.run`` (and the command line) call every iteration by default.

    python benchmarks/bench_iteration.py [--sizes 64 128 256] [--repeats 5] [--device cpu]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from numpy_step import OCTANT, dense_step, flow_inputs, flow_step  # noqa: E402

from warpspec.solver import FULL_REINIT_EVERY  # noqa: E402

CPU_SIZES = (64, 128, 256)
CUDA_SIZES = (64, 128, 256, 512)


def _sizes(values: list[str] | None, is_cuda: bool) -> tuple[list[int], list[str]]:
    if not values:
        return list(CUDA_SIZES if is_cuda else CPU_SIZES), []
    sizes = [int(v) for item in values for v in str(item).split(",") if v]
    notes = []
    if not is_cuda and any(s > 256 for s in sizes):
        notes.append("sizes above 256^3 run only on CUDA: skipped "
                     + ", ".join(f"{s}^3" for s in sizes if s > 256))
        sizes = [s for s in sizes if s <= 256]
    return sizes, notes


def _timed(fn, sync) -> float:
    sync()
    t0 = time.perf_counter()
    fn()
    sync()
    return time.perf_counter() - t0


def measure(size: int, *, device, repeats: int, iterations: int | None, breakdown: bool,
            numpy_repeats: int | None = None) -> dict:
    """Time NumPy step, dense kernel and solver iteration at one size (seconds, medians)."""
    import warp as wp

    import warpspec as ws

    def sync():
        wp.synchronize_device(device)

    t0 = time.perf_counter()
    solver = ws.Reconstructor(ws.Scene.load(OCTANT), resolution=size, device=device)
    sync()
    setup = time.perf_counter() - t0
    grid = solver.grid
    voxels = grid.size
    owner, normals, gauss = (a.numpy() for a in flow_inputs(solver))
    phi = solver.phi
    out = wp.empty(grid.shape, dtype=float, device=device)
    # A block covers a whole cycle of reinitialisations: band-only ones and the full one that
    # comes every FULL_REINIT_EVERY-th time, so the amortised cost counts both.
    every = max(solver.reinit_every, 1) * FULL_REINIT_EVERY

    # warm up every launch path (first launches load modules), then calibrate batch sizes
    dense_step(solver, out)
    solver.step()
    solver.measures()
    t_kernel = _timed(lambda: dense_step(solver, out), sync)
    kernel_batch = max(1, min(1000, math.ceil(0.05 / max(t_kernel, 1e-9))))
    if iterations is None:
        t_step = _timed(solver.step, sync)
        iterations = every * max(1, math.ceil(0.2 / max(t_step * every, 1e-9)))
    n_steps = every * max(1, math.ceil(iterations / every))

    def kernel_block():
        for _ in range(kernel_batch):
            dense_step(solver, out)

    def iteration_block():
        for _ in range(n_steps):
            solver.step()

    numpy_repeats = repeats if numpy_repeats is None else numpy_repeats
    times = {"numpy": [], "kernel": [], "iteration": []}
    for r in range(repeats):
        if r < numpy_repeats:
            t0 = time.perf_counter()
            flow_step(phi, owner, normals, gauss, spacing=grid.spacing, dt=solver.dt,
                      alpha=solver.alpha, point_weight=solver.w_point)
            times["numpy"].append(time.perf_counter() - t0)
        times["kernel"].append(_timed(kernel_block, sync) / kernel_batch)
        times["iteration"].append(_timed(iteration_block, sync) / n_steps)

    result = {
        "size": size,
        "shape": list(grid.shape),
        "voxels": voxels,
        "setup_s": setup,
        "iterations_timed": n_steps,
        "reinit_every": solver.reinit_every,
        "kernel_batch": kernel_batch,
        "repeats": repeats,
        **{f"{k}_s": statistics.median(v) for k, v in times.items()},
        **{f"{k}_runs_s": v for k, v in times.items()},
    }
    if breakdown:
        result.update(_breakdown(solver, sync, repeats))
    return result


def _breakdown(solver, sync, repeats: int) -> dict:
    """Median seconds of the iteration's parts (reinitialisation switched off meanwhile)."""
    every = solver.reinit_every
    parts = {"step_no_intersect": [], "step_no_reinit": [], "reinitialize": [], "measures": []}
    try:
        solver.reinit_every = 0
        for _ in range(repeats):
            parts["step_no_intersect"].append(
                _timed(lambda: solver._step(intersect=False), sync))
            parts["step_no_reinit"].append(_timed(solver.step, sync))
            parts["reinitialize"].append(_timed(solver.reinitialize, sync))
            parts["measures"].append(_timed(solver.measures, sync))
    except TypeError as exc:  # the step's signature changed: leave the split out
        return {"breakdown_error": str(exc)}
    finally:
        solver.reinit_every = every
    return {f"{k}_s": statistics.median(v) for k, v in parts.items()}


def _ms(seconds: float) -> str:
    ms = 1e3 * seconds
    return f"{ms:.3g}" if ms < 100 else f"{ms:.0f}"


def _difference(a: float, b: float) -> str:
    """``a - b`` in ms, or ``~0`` where noise makes it negative."""
    return _ms(a - b) if a > b else "~0"


def _mvox(voxels: int, seconds: float) -> str:
    return f"{voxels / seconds / 1e6:.1f}"


def tables(results: list[dict]) -> str:
    """The markdown tables of :func:`measure`'s results."""
    lines = [
        "| grid | voxels | NumPy step (ms) | NumPy Mvox/s | warpspec step kernel (ms) "
        "| kernel Mvox/s | warpspec iteration (ms) | iteration Mvox/s "
        "| NumPy / kernel | NumPy / iteration |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        v = r["voxels"]
        lines.append(
            f"| {r['size']}^3 ({'x'.join(map(str, r['shape']))}) | {v / 1e6:.2f} M "
            f"| {_ms(r['numpy_s'])} | {_mvox(v, r['numpy_s'])} "
            f"| {_ms(r['kernel_s'])} | {_mvox(v, r['kernel_s'])} "
            f"| {_ms(r['iteration_s'])} | {_mvox(v, r['iteration_s'])} "
            f"| {r['numpy_s'] / r['kernel_s']:.2f}x | {r['numpy_s'] / r['iteration_s']:.2f}x |"
        )
    split = [r for r in results if "reinitialize_s" in r]
    if split:
        lines += [
            "",
            "Where an iteration goes (ms, medians; reinitialisation off while splitting):",
            "",
            "| grid | setup (s) | flow kernel | step(intersect=False) | step(), no reinit "
            "| of which intersect + claim | reinitialize() | reinit amortised "
            "| sum | iteration | measures() |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in split:
            every = max(r["reinit_every"], 1)
            amortised = r["reinitialize_s"] / every
            lines.append(
                f"| {r['size']}^3 | {r['setup_s']:.2f} | {_ms(r['kernel_s'])} "
                f"| {_ms(r['step_no_intersect_s'])} | {_ms(r['step_no_reinit_s'])} "
                f"| {_difference(r['step_no_reinit_s'], r['step_no_intersect_s'])} "
                f"| {_ms(r['reinitialize_s'])} | {_ms(amortised)} "
                f"| {_ms(r['step_no_reinit_s'] + amortised)} | {_ms(r['iteration_s'])} "
                f"| {_ms(r['measures_s'])} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=None,
                        help="grid resolutions (default 64 128 256; 512 too on CUDA)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per row (median)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="steps per timed iteration block, rounded up to a multiple of "
                             "reinit_every (default: reinit_every on the CPU, enough for "
                             "0.2 s on CUDA)")
    parser.add_argument("--numpy-repeats", type=int, default=None,
                        help="NumPy runs per row (default: --repeats)")
    parser.add_argument("--no-breakdown", action="store_true",
                        help="skip the table that splits the iteration into its parts")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda, cuda:0)")
    parser.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)

    import warp as wp

    from warpspec._runtime import resolve_device

    device = resolve_device(args.device)
    sizes, notes = _sizes(args.sizes, device.is_cuda)
    if args.iterations is None and not device.is_cuda:
        args.iterations = 10
    results = []
    for size in sizes:
        results.append(measure(size, device=device, repeats=args.repeats,
                               iterations=args.iterations, breakdown=not args.no_breakdown,
                               numpy_repeats=args.numpy_repeats))
    print(f"Octant scene at resolution N, default options; warp {wp.__version__}, device "
          f"{device.alias} ({device.name}); NumPy {np.__version__} on the host; medians of "
          f"{args.repeats} interleaved runs; an iteration is timed over "
          f"{', '.join(str(r['iterations_timed']) for r in results)} steps "
          f"(reinit every {results[0]['reinit_every'] if results else '-'}).")
    for note in notes:
        print(f"Note: {note}.")
    print()
    print(tables(results))
    if args.json:
        Path(args.json).write_text(json.dumps({"device": device.alias, "device_name":
                                               device.name, "rows": results}, indent=1))
    return results


if __name__ == "__main__":
    main()
