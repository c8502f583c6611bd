"""Benchmark: the time of each stage of a reconstruction, on every shape class.

For each synthetic scene of the shape classes (seed 0) and the paper's octant, at one grid
(default 64) with the default options: the set-up's stages as the implicit start announces
them (the quadric; the ring torus and the surface of revolution, tried when the cameras stand
all around; the robust passes on the coarse grids; the cross-validation passes on the
coarsest; the ladder of grid fits, and the ladder
again when rejected highlights come back or the points are weighed as noisy; the points left
out one at a time), the rest of the set-up (redistance, the band, the
device arrays), the flow's iterations (as many as the grid's schedule gives) and the meshing.
Seconds, medians of ``--repeats`` runs in one process, after one untimed run that loads the
kernels.

    python benchmarks/bench_start.py [--resolution 64] [--repeats 1] [--device cpu]
    python benchmarks/bench_start.py --smoke      # 16^3, two scenes: checks the script
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SCENES = ("octant", "sphere-around", "ellipsoid-around", "pebble", "torus", "torus-lamps",
          "torus-point", "blob", "bottle", "bottle-lamps", "wrap", "freeform", "point-light")
STAGES = ("quadric", "torus", "revolution", "robust passes", "cross-validation", "grid fit",
          "grid fit again", "points judged", "other set-up", "iterations", "meshing", "total")


def _stage(text: str) -> str:
    for prefix, name in (("a quadric", "quadric"), ("an ellipsoid", "quadric"),
                         ("a ring torus", "torus"),
                         ("a surface of revolution", "revolution"),
                         ("robust pass", "robust passes"),
                         ("cross-validation pass", "cross-validation"), ("grid ", "grid fit"),
                         ("the ladder again", "grid fit again"),
                         ("the points left out", "points judged"),
                         ("the start redistanced", "other set-up")):
        if text.startswith(prefix):
            return name
    return "other set-up"


def measure(name: str, *, resolution: int, device: str | None) -> dict[str, float]:
    """Seconds per stage of one reconstruction of one scene."""
    import warp as wp

    import warpspec as ws
    from warpspec.options import default_iterations
    from warpspec.synthetic import make_scene

    scene = make_scene(name).scene()
    marks: list[tuple[float, str]] = []

    def progress(text: str) -> None:
        wp.synchronize()
        marks.append((time.perf_counter(), text))

    times = dict.fromkeys(STAGES, 0.0)
    t0 = time.perf_counter()
    solver = ws.Reconstructor(scene, resolution=resolution, device=device, progress=progress)
    wp.synchronize()
    t1 = time.perf_counter()
    ends = [t for t, _ in marks[1:]] + [t1]
    for (start, text), end in zip(marks, ends, strict=True):
        times[_stage(text)] += end - start
    times["other set-up"] += (t1 - t0) - sum(end - start for (start, _), end in zip(marks, ends,
                                                                                      strict=True))
    solver.run(default_iterations(resolution), measure_every=0)
    wp.synchronize()
    t2 = time.perf_counter()
    solver.result()
    t3 = time.perf_counter()
    times["iterations"] = t2 - t1
    times["meshing"] = t3 - t2
    times["total"] = t3 - t0
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=64, help="grid cells (default 64)")
    parser.add_argument("--repeats", type=int, default=1, help="timed runs per scene (median)")
    parser.add_argument("--device", default=None, help="Warp device (default: CUDA if seen)")
    parser.add_argument("--smoke", action="store_true", help="16^3, two scenes, one run")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.resolution < 8:
        parser.error("--repeats: at least 1; --resolution: at least 8")
    scenes = ("octant", "torus") if args.smoke else SCENES
    resolution = 16 if args.smoke else args.resolution

    import warp as wp

    import warpspec as ws
    from warpspec._runtime import resolve_device

    device = resolve_device(args.device)
    measure(scenes[0], resolution=resolution, device=device)  # load the kernels, untimed
    print(f"Each scene (seed 0) at {resolution}^3, default options, device {device.alias}; "
          f"warpspec {ws.__version__}, warp {wp.__version__}; seconds, median of "
          f"{args.repeats} run(s) in one process.\n")
    print("| scene | " + " | ".join(STAGES) + " |")
    print("|---|" + "---|" * len(STAGES))
    for name in scenes:
        runs = [measure(name, resolution=resolution, device=device) for _ in range(args.repeats)]
        row = [statistics.median(r[s] for r in runs) for s in STAGES]
        print(f"| {name} | " + " | ".join("-" if v == 0.0 else f"{v:.2f}" for v in row) + " |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
