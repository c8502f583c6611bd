"""Benchmark: reinitialisation of a sphere by warpspec.redistance against scikit-fmm.

The input is phi = (|x - c|^2 - R^2) / (2R) on the unit cube (n nodes a side, R = 0.3, the
centre off the grid's symmetry), which has the sphere as its zero set but is not a distance.
Each row gives the best of ``--repeats`` wall-clock times of one call (NumPy in, NumPy out,
host-device copies included; the runs take turns), the speed-up over scikit-fmm order 1, and
the largest error against the exact distance |x - c| - R, in voxels (h), over the nodes with
|d| < 3h (the narrow band next to the surface) and over |d| < 6h.

Rows with ``cap=8h`` compute the distance only within 8 voxels of the surface (farther nodes
read +-8h), the cap the solver's full redistances use (``BandTracker.far_cap``: the narrow
band's 4 voxels plus 4), against scikit-fmm's own narrow band (``narrow=8h``): what a
narrow-band solver needs. Each warpspec row's speed-up is against its fair peer: the full
distance against scikit-fmm order 1, the capped one against scikit-fmm order 1 narrowed to the
same width.

    python benchmarks/bench_redistance.py [--large] [--sizes 64 128] [--repeats 3] [--device cpu]
    python benchmarks/bench_redistance.py --smoke      # 24^3, one call: checks the script
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def sphere(n: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Spacing, the level set (not a distance) and the exact signed distance."""
    h = 1.0 / (n - 1)
    x = np.arange(n) * h
    xx, yy, zz = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt((xx - 0.5) ** 2 + (yy - 0.52) ** 2 + (zz - 0.48) ** 2)
    radius = 0.3
    return h, (r**2 - radius**2) / (2.0 * radius), r - radius


def best_times(runs: dict, repeats: int) -> dict[str, tuple[float, np.ndarray]]:
    """Smallest wall-clock time of ``repeats`` calls of each run, and its result.

    The runs take turns (round robin), so that a slow spell of a shared machine does not fall
    on one of them only.
    """
    best = {name: (float("inf"), None) for name in runs}
    for _ in range(repeats):
        for name, fn in runs.items():
            t0 = time.perf_counter()
            out = fn()
            seconds = time.perf_counter() - t0
            if seconds < best[name][0]:
                best[name] = (seconds, out)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--large", action="store_true", help="also run 256^3 (minutes)")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per row (best)")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda:0)")
    parser.add_argument("--sizes", nargs="+", type=int, default=None,
                        help="grid sizes (default 64 128, and 256 with --large)")
    parser.add_argument("--smoke", action="store_true", help="24^3, one call per row")
    parser.add_argument("--no-peers", action="store_true",
                        help="time warpspec only (scikit-fmm takes minutes at 512^3)")
    parser.add_argument(
        "--cold-cache",
        action="store_true",
        help="compile into an empty kernel cache, to report the cold compile time",
    )
    args = parser.parse_args()
    if args.cold_cache:
        os.environ["WARP_CACHE_PATH"] = tempfile.mkdtemp(prefix="warpspec-bench-cache-")

    import skfmm
    import warp as wp

    from warpspec import _runtime
    from warpspec.kernels import redistance as kernels
    from warpspec.options import DEFAULTS
    from warpspec.redistance import redistance
    from warpspec.solver.tracker import FAR_CAP_MARGIN

    t0 = time.perf_counter()
    _runtime.init()
    t_init = time.perf_counter() - t0
    device = _runtime.resolve_device(args.device)
    t0 = time.perf_counter()
    wp.load_module(kernels, device=device)
    t_load = time.perf_counter() - t0
    # warm up the launch path (and the per-shape Redistancer) outside the timings
    h, phi, _ = sphere(16)
    redistance(phi, h, device=device)

    cap = DEFAULTS["narrow_band"] + FAR_CAP_MARGIN  # voxels, as the solver caps
    capped = f"cap={cap:g}h"
    narrow = f"skfmm order 1 narrow={cap:g}h"
    sizes = args.sizes or [64, 128] + ([256] if args.large else [])
    if args.smoke:
        sizes, args.repeats = [24], 1
    rows = []
    for n in sizes:
        h, phi, exact = sphere(n)
        near = np.abs(exact) < 3 * h
        wide = np.abs(exact) < 6 * h
        runs = {} if args.no_peers else {
            "skfmm order 1": lambda phi=phi, h=h: skfmm.distance(phi, dx=h, order=1),
            "skfmm order 2": lambda phi=phi, h=h: skfmm.distance(phi, dx=h, order=2),
        }
        for band in ("gradient", "axis"):
            runs[f"warpspec {device.alias} band={band}"] = lambda phi=phi, h=h, band=band: (
                redistance(phi, h, device=device, band=band)
            )
        if not args.no_peers:
            runs[narrow] = lambda phi=phi, h=h: np.asarray(
                skfmm.distance(phi, dx=h, order=1, narrow=cap * h).filled(np.nan))
        runs[f"warpspec {device.alias} band=gradient {capped}"] = lambda phi=phi, h=h: (
            redistance(phi, h, device=device, cap=cap * h))
        results = {}
        for name, (seconds, d) in best_times(runs, args.repeats).items():
            err = np.abs(d - exact) / h
            results[name] = (seconds, np.nanmax(err[near]), np.nanmax(err[wide]))
        for name, (seconds, e3, e6) in results.items():
            # scikit-fmm's own rows against its full order 1, as the full warpspec rows
            peer = narrow if capped in name else "skfmm order 1"
            ref = results.get(peer)
            speed = f"{ref[0] / seconds:.1f}x" if ref else "not run"
            ratio = f"{e3 / ref[1]:.2f}" if ref else "not run"
            rows.append(f"| {n}^3 | {name} | {seconds:.3f} | {peer} | {speed} | {e3:.3f} "
                        f"| {ratio} | {e6:.3f} |")

    print(f"warp {wp.__version__}, device {device.alias}: init {t_init:.2f} s, module load")
    print(f"{t_load:.2f} s ({'cold compile' if args.cold_cache else 'compile or cache hit'}),")
    print(f"best of {args.repeats} calls; errors in h against the exact sphere distance.\n")
    print("| grid | method | time (s) | peer | speed-up vs peer | max err, abs(d) < 3h "
          "| err / peer's | max err, abs(d) < 6h |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
