"""Reconstruct a scene of every shape class with the default options and score it.

The yardstick for making the solver reconstruct any shape: closed objects (a sphere and an
ellipsoid seen all around, a torus), a bottle open at the domain's ends, a patch that wraps
past 180 degrees, free-form and point-lit height fields, plus the paper's scenes. Each scene is
built by ``warpspec synth``'s generator (``warpspec.synthetic.make_scene``), reconstructed with
``warpspec.reconstruct(scene, resolution=..., iterations=...)`` and DEFAULT options, and
scored with ``warpspec.evaluate`` against the truth:

- open scenes are cropped to the constraints' hull as ``warpspec evaluate`` does by default
  (the hull of the true specular points of the inliers and the point constraints);
- closed scenes are scored over the whole surface, and their mesh is checked for
  watertightness and its Euler number against the truth's (2 for a sphere, 0 for a torus).

Columns of the markdown table it prints:

- truth->mesh / mesh->truth: mean distance from the truth's samples to the mesh
  (completeness) and back (accuracy), in voxel widths h of the solver's grid;
- watertight: whether the mesh is closed (closed scenes only);
- Euler: the mesh's Euler number / the truth's;
- vs clean: for a noise or outlier variant, the symmetric mean distance (h) between its mesh
  and the clean scene's mesh (same seed), open scenes cropped to the clean scene's hull;
- excess: for a variant, its symmetric mean distance to the truth (h) minus the clean
  scene's: how much the noise or the false highlights cost against the truth;
- misses: rays that do not meet the final surface (the solver's count after the last
  iteration); time: seconds for the reconstruction alone (kernels compiled beforehand).

The paper's scenes have a fixed geometry and run once (with the first seed); the shape-class
scenes run once per seed, their shape varied by it.

Examples:
    python examples/any_shape.py                                   # every scene, seeds 0 1 2
    python examples/any_shape.py --scene torus wrap --seeds 0 --resolution 32
    python examples/any_shape.py --outliers 0.1 0.25 --noise 0.5 --json rows.json
    python examples/any_shape.py --scene freeform --highlights 30 60 120 240
    python examples/any_shape.py --write-scenes examples/scenes      # the example files
    python examples/any_shape.py --summary-of rows.json more.json      # the README's table

``--summary`` (or ``--summary-of`` saved rows) prints one row per scene: means and worsts over
the seeds, the closed meshes that are watertight with the truth's Euler number, and each
variant's worst excess over the clean scene (and how many seeds exceed 0.1 h).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import warpspec
from warpspec.errors import InputError, ReconstructionError, SceneError
from warpspec.evaluate import evaluate, truth_region
from warpspec.synthetic import SyntheticScene, make_scene

SHAPES = ("sphere-around", "ellipsoid-around", "pebble", "torus", "torus-lamps", "torus-point",
          "blob", "bottle", "bottle-lamps", "wrap", "freeform", "point-light")
PAPER = ("octant", "ellipsoid-cap", "car-window", "wine-bottle")
# Truth meshes written next to the example scene files: coarse, to keep the folder small
# (``warpspec synth NAME --truth MESH`` writes the full-resolution one).
PLY_OPTIONS = {
    "sphere-around": {"subdivisions": 3},
    "ellipsoid-around": {"subdivisions": 3},
    "pebble": {"subdivisions": 3},
    "torus": {"sections": 48, "tube": 16},
    "torus-lamps": {"sections": 48, "tube": 16},
    "torus-point": {"sections": 48, "tube": 16},
    "blob": {"subdivisions": 3},
    "bottle": {"sections": 32},
    "bottle-lamps": {"sections": 32},
    "wrap": {"sections": 32},
    "freeform": {"resolution": 32},
    "point-light": {"resolution": 32},
}
COLUMNS = ("scene", "seed", "variant", "highlights", "points", "truth->mesh (h)",
           "mesh->truth (h)", "watertight", "Euler", "vs clean (h)", "excess (h)", "misses",
           "time (s)")


ACCEPT_EXCESS = 0.1
"""The excess over the clean scene (h) a false-highlight variant should stay within."""


def _variants(noise: list[float], outliers: list[float]) -> list[tuple[str, float, float]]:
    out = [("clean", 0.0, 0.0)]
    out += [(f"noise {n:g} px", n, 0.0) for n in noise]
    out += [(f"outliers {f:g}", 0.0, f) for f in outliers]
    return out


def run_one(synthetic: SyntheticScene, *, resolution: int, iterations: int,
            device: str | None, samples: int) -> tuple[dict, object | None, float | None]:
    """Reconstruct one scene and score it; returns the row, the mesh and the spacing."""
    row: dict = {"highlights": len(synthetic.truth_points), "points": len(synthetic.points),
                 "closed": synthetic.closed, "euler_expected": synthetic.euler}
    start = time.perf_counter()
    try:
        result = warpspec.reconstruct(synthetic.scene(), resolution=resolution,
                                      iterations=iterations, device=device)
    except (ReconstructionError, SceneError) as exc:
        row.update(error=str(exc), time=time.perf_counter() - start)
        return row, None, None
    row["time"] = time.perf_counter() - start
    mesh = result.mesh.copy()
    mesh.merge_vertices()
    h = float(result.grid.spacing)
    row["misses"] = result.history[-1].get("misses") if result.history else None
    if len(mesh.faces) == 0:
        row["error"] = "empty mesh"
        return row, None, h
    keep = synthetic.inliers
    region = scoring_region(synthetic)
    try:
        ev = evaluate(mesh, synthetic.truth_mesh(), spacing=h, region=region,
                      specular_points=synthetic.truth_points[keep],
                      true_normals=synthetic.truth_normals[keep], samples=samples)
    except InputError as exc:
        row["error"] = str(exc)
        return row, mesh, h
    row.update(completeness=ev.completeness.mean / h, accuracy=ev.accuracy.mean / h,
               normal_angle_mean=ev.normal_angle_mean, euler=int(mesh.euler_number),
               watertight=bool(mesh.is_watertight))
    return row, mesh, h


def scoring_region(synthetic: SyntheticScene):
    """The region an open scene is scored over (the inliers' hull), ``None`` for a closed one."""
    if synthetic.closed:
        return None
    return truth_region(synthetic.truth_points[synthetic.inliers], synthetic.points)


def _symmetric(row: dict) -> float | None:
    if "completeness" not in row:
        return None
    return 0.5 * (row["completeness"] + row["accuracy"])


def _label(row: dict) -> str:
    """The scene's name, with the highlights asked for where they were (``--highlights``)."""
    count = row.get("requested")
    return row["scene"] if count is None else f"{row['scene']}, {count} highlights"


def summary(rows: list[dict]) -> list[str]:
    """The per-scene summary table (markdown lines) of ``rows``: the clean rows' means and
    worsts over the seeds, and each variant's worst excess over the clean scene."""
    variants = list(dict.fromkeys(r["variant"] for r in rows if r["variant"] != "clean"))
    head = ["scene", "seeds", "truth->mesh (h), mean / worst", "mesh->truth (h), mean / worst",
            "watertight, right Euler", *(f"excess (h), worst: {v}" for v in variants)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in dict.fromkeys(_label(r) for r in rows):
        mine = [r for r in rows if _label(r) == key]
        clean = [r for r in mine if r["variant"] == "clean"]
        scored = [r for r in clean if "completeness" in r]
        cells = [key, str(len(clean))]
        for measure in ("completeness", "accuracy"):
            values = [r[measure] for r in scored]
            cells.append(f"{np.mean(values):.3f} / {np.max(values):.3f}" if values else "-")
        if clean and clean[0]["closed"]:
            good = sum(bool(r.get("watertight")) and r.get("euler") == r["euler_expected"]
                       for r in scored)
            cells.append(f"{good} of {len(clean)}")
        else:
            cells.append("open")
        for variant in variants:
            values = [r["excess"] for r in mine if r["variant"] == variant
                      and r.get("excess") is not None]
            failed = sum(r["variant"] == variant and "error" in r for r in mine)
            over = sum(x > ACCEPT_EXCESS for x in values)
            text = f"{_fmt(max(values), '+.3f')} ({over} over)" if values else "-"
            cells.append(text + (f" ({failed} failed)" if failed else ""))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _fmt(value, spec: str = ".3f") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, float):
        value = round(value, 3) + 0.0  # no "-0.000"
    return format(value, spec)


def table_row(row: dict) -> str:
    """One markdown row of :data:`COLUMNS`."""
    if "error" in row and "completeness" not in row:
        tail = [f"failed: {row['error']}", "-", "-", "-", "-", "-", _fmt(row.get("misses"), "d"),
                _fmt(row.get("time"), ".1f")]
    else:
        watertight = ("yes" if row["watertight"] else "no") if row["closed"] else "-"
        tail = [_fmt(row["completeness"]), _fmt(row["accuracy"]), watertight,
                f"{row['euler']} / {_fmt(row['euler_expected'], 'd')}",
                _fmt(row.get("vs_clean")), _fmt(row.get("excess"), "+.3f"),
                _fmt(row.get("misses"), "d"), _fmt(row["time"], ".1f")]
    cells = [row["scene"], str(row["seed"]), row["variant"], str(row["highlights"]),
             str(row["points"]), *tail]
    return "| " + " | ".join(cells) + " |"


def write_scenes(folder: Path, seed: int) -> None:
    """Write each shape-class scene (NAME.json, NAME.truth.json, a coarse NAME.ply)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in SHAPES:
        synthetic = make_scene(name, seed=seed)
        synthetic.to_json(folder / f"{name}.json")
        text = json.dumps(synthetic.truth_dict(), indent=1) + "\n"
        (folder / f"{name}.truth.json").write_text(text)
        synthetic.truth_mesh(**PLY_OPTIONS[name]).export(folder / f"{name}.ply")
        print(f"{name}: {len(synthetic.truth_points)} highlights, {len(synthetic.points)} "
              f"points -> {folder / name}.json, .truth.json, .ply")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        epilog="Scenes: " + ", ".join(SHAPES + PAPER))
    parser.add_argument("--scene", nargs="+", default=None, metavar="NAME",
                        help="run only these scenes (default: every one listed below)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], metavar="S",
                        help="seeds of the shape-class scenes (default: 0 1 2)")
    parser.add_argument("--noise", nargs="*", type=float, default=[], metavar="PX",
                        help="also run each scene with this pixel noise (e.g. 0.5)")
    parser.add_argument("--outliers", nargs="*", type=float, default=[], metavar="F",
                        help="also run each scene with this fraction of false highlights "
                             "(e.g. 0.1 0.25)")
    parser.add_argument("--highlights", nargs="+", type=int, default=None, metavar="N",
                        help="run freeform with each of these highlight counts (e.g. 30 60 "
                             "120 240; default: its own)")
    parser.add_argument("--resolution", type=int, default=64, help="grid cells (default 64)")
    parser.add_argument("--iterations", type=int, default=300, help="iterations (default 300)")
    parser.add_argument("--samples", type=int, default=20_000,
                        help="evaluation samples per mesh (default 20000)")
    parser.add_argument("--device", default=None, help="Warp device (default: CUDA if seen)")
    parser.add_argument("--summary", action="store_true",
                        help="also print the per-scene summary table after the rows")
    parser.add_argument("--summary-of", nargs="+", type=Path, default=None, metavar="FILE",
                        help="only print the summary table of rows saved with --json (several "
                             "files are merged), and stop")
    parser.add_argument("--json", type=Path, default=None, metavar="FILE",
                        help="also write the rows to this file (.json)")
    parser.add_argument("--write-scenes", type=Path, default=None, metavar="DIR",
                        help="only write the shape-class scenes (first seed) into DIR, with "
                             "their truth and a coarse truth mesh, and stop")
    args = parser.parse_args(argv)
    if args.summary_of is not None:
        rows = []
        for path in args.summary_of:
            try:
                rows += json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                parser.error(f"--summary-of: cannot read rows from {str(path)!r}: {exc}")
        print("\n".join(summary(rows)))
        return 0
    if args.write_scenes is not None:
        write_scenes(args.write_scenes, args.seeds[0] if args.seeds else 0)
        return 0

    names = list(args.scene) if args.scene else [*SHAPES, *PAPER]
    unknown = [n for n in names if n not in SHAPES + PAPER]
    if unknown:
        parser.error(f"--scene: unknown {unknown}; expected some of {list(SHAPES + PAPER)}")
    if not args.seeds:
        parser.error("--seeds: give at least one seed")
    for f in args.outliers:
        if not 0 < f < 1:
            parser.error(f"--outliers: each fraction must lie in (0, 1), got {f:g}")
    if args.json is not None and args.json.suffix.lower() != ".json":
        parser.error(f"--json: expected a .json file, got {str(args.json)!r}")

    # Compile (or load) the kernels first, so that no row's time includes compilation.
    warpspec.reconstruct(make_scene("octant").scene(), resolution=12, iterations=2,
                         device=args.device)
    print("| " + " | ".join(COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    rows = []
    for name in names:
        seeds = args.seeds if name in SHAPES else args.seeds[:1]
        counts = args.highlights if name == "freeform" and args.highlights else [None]
        for seed, count in ((s, c) for s in seeds for c in counts):
            options = {} if count is None else {"highlights": count}
            clean_mesh = clean_score = clean_region = None
            for label, noise, outliers in _variants(args.noise, args.outliers):
                synthetic = make_scene(name, noise=noise, outliers=outliers, seed=seed,
                                       **options)
                row, mesh, h = run_one(synthetic, resolution=args.resolution,
                                       iterations=args.iterations, device=args.device,
                                       samples=args.samples)
                row.update(scene=name, seed=seed, variant=label, requested=count)
                if label == "clean":
                    clean_mesh, clean_score = mesh, _symmetric(row)
                    clean_region = scoring_region(synthetic)
                elif mesh is not None and clean_mesh is not None:
                    try:
                        ev = evaluate(mesh, clean_mesh, spacing=h, region=clean_region,
                                      samples=args.samples)
                        row["vs_clean"] = ev.chamfer / h
                    except InputError:  # the crop keeps nothing of one mesh
                        row["vs_clean"] = None
                    if _symmetric(row) is not None and clean_score is not None:
                        row["excess"] = _symmetric(row) - clean_score
                rows.append(row)
                print(table_row(row), flush=True)
    if args.summary:
        print()
        print("\n".join(summary(rows)))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1, default=_json_default) + "\n")
    return 0


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


if __name__ == "__main__":
    sys.exit(main())
