"""The ``warpspec`` command line: a thin layer over the Python API.

Errors in the input are reported as one line on standard error with exit status 2; a run
that fails for another reason (a non-finite level set, no surface) exits with status 1.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from .errors import ReconstructionError, SceneError

__all__ = ["main"]

MESH_FORMATS = (".ply", ".obj", ".stl", ".glb", ".off")
METRIC_FORMATS = (".csv", ".json")


def _version() -> str:
    from . import __version__

    return __version__


def atomic_write(path: Path, write) -> None:
    """Call ``write(tmp_path)`` then rename the temporary file onto ``path``.

    An interrupted run never leaves a half-written file at ``path``.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.part{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _suffix(path: str, allowed: Sequence[str], flag: str) -> Path:
    p = Path(path)
    if p.suffix.lower() not in allowed:
        raise SceneError(
            f"{flag}: {path!r} has an unsupported extension; use one of {', '.join(allowed)}"
        )
    if not p.parent.exists():
        raise SceneError(f"{flag}: the folder {str(p.parent)!r} does not exist")
    return p


def write_metrics(path: Path, history: list[dict]) -> None:
    """Write the per-iteration measures as CSV or JSON (by the file's extension)."""

    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    def write(tmp: Path) -> None:
        if path.suffix.lower() == ".json":
            rows = [{k: clean(v) for k, v in row.items()} for row in history]
            tmp.write_text(json.dumps(rows, indent=1) + "\n")
        else:
            with open(tmp, "w", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=list(history[0]))
                writer.writeheader()
                writer.writerows(history)

    atomic_write(path, write)


def write_mesh(path: Path, mesh) -> None:
    """Export a mesh in the format its extension names, atomically."""
    atomic_write(path, lambda tmp: mesh.export(tmp, file_type=path.suffix.lower()[1:]))


class _Progress:
    """A progress bar over iterations (tqdm), or nothing when quiet or not on a terminal."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="it", file=sys.stderr, leave=True)
        self.last = 0

    def __call__(self, m: dict) -> None:
        if self.bar is None:
            return
        self.bar.update(m["iteration"] - self.last)
        self.last = m["iteration"]
        self.bar.set_postfix(normal=f"{m['normal_error']:.4f}",
                             point=f"{m['point_error']:.3f}h", misses=m["misses"],
                             refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    from .scene import Scene
    from .solver import Reconstructor

    out = _suffix(args.output, MESH_FORMATS, "--output")
    metrics = _suffix(args.metrics, METRIC_FORMATS, "--metrics") if args.metrics else None
    save_phi = _suffix(args.save_phi, (".npz",), "--save-phi") if args.save_phi else None
    if args.crop not in (None, "hull"):
        raise SceneError(f"--crop: unknown crop {args.crop!r}; use 'hull'")
    scene = Scene.load(args.scene)
    if not args.quiet:
        scene.check()
    start = time.perf_counter()
    solver = Reconstructor(
        scene,
        resolution=args.resolution,
        alpha=args.alpha,
        bulge=args.bulge,
        bulge_cap=args.bulge_cap,
        device=args.device,
        reinit_every=args.reinit_every,
        resume=args.resume,
    )
    progress = _Progress(args.iterations, enabled=not args.quiet and sys.stderr.isatty())
    try:
        solver.run(args.iterations, measure_every=1, callback=progress)
    finally:
        progress.close()
    result = solver.result()
    mesh = result.mesh
    if args.crop == "hull":
        from .mesh import crop_to_hull

        mesh = crop_to_hull(mesh, result.constraint_anchors(scene))
    write_mesh(out, mesh)
    if metrics is not None:
        write_metrics(metrics, result.history)
    if save_phi is not None:
        result.save_phi(save_phi)
    if not args.quiet:
        last = result.history[-1]
        print(
            f"wrote {out} ({len(mesh.faces)} faces) in {time.perf_counter() - start:.1f} s: "
            f"normal error {last['normal_error']:.4g}, point error {last['point_error']:.3g} "
            f"voxel, {last['misses']} missed rays",
            file=sys.stderr,
        )
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    import warp as wp

    from ._runtime import init

    init()
    print(f"warpspec {_version()}")
    print(f"warp {wp.__version__}")
    for d in wp.get_devices():
        extra = f", {d.total_memory / 2**30:.1f} GiB" if d.is_cuda else ""
        print(f"device {d.alias}: {d.name}{extra}")
    print(f"kernel cache {wp.config.kernel_cache_dir}")
    return 0


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``warpspec`` command."""
    parser = argparse.ArgumentParser(
        prog="warpspec",
        description="Reconstruct shiny surfaces from sparse points and specular highlights.",
    )
    parser.add_argument("--version", action="version", version=f"warpspec {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rec = sub.add_parser("reconstruct", help="reconstruct a surface mesh from a scene file",
                         description="Reconstruct a surface mesh from a scene file.")
    rec.add_argument("scene", help="scene file (JSON, version 1)")
    rec.add_argument("-o", "--output", required=True,
                     help=f"mesh to write; format by extension ({', '.join(MESH_FORMATS)})")
    rec.add_argument("--resolution", type=_positive_int, default=64,
                     help="cells along the longest side of the domain (default 64)")
    rec.add_argument("--iterations", type=_positive_int, default=300,
                     help="iterations of the flow (default 300)")
    rec.add_argument("--alpha", type=_finite, default=0.01,
                     help="weight of the smoothness term (default 0.01)")
    rec.add_argument("--bulge", type=_finite, default=0.0,
                     help="bend the initial plane toward the cameras by this times the "
                          "distance to the nearest point (default 0)")
    rec.add_argument("--bulge-cap", type=_finite, default=None,
                     help="cap on that distance, in voxel widths (default: none)")
    rec.add_argument("--reinit-every", type=int, default=10,
                     help="reinitialise to a signed distance every N iterations (default 10)")
    rec.add_argument("--device", default=None,
                     help="Warp device: cpu, cuda, cuda:0 (default: CUDA if present)")
    rec.add_argument("--metrics", default=None,
                     help="write the per-iteration measures (.csv or .json)")
    rec.add_argument("--save-phi", default=None, help="keep the level set and its grid (.npz)")
    rec.add_argument("--resume", default=None, help="continue from a level set saved with "
                                                    "--save-phi")
    rec.add_argument("--crop", default=None, choices=["hull"],
                     help="keep only the faces inside the hull of the constraints")
    rec.add_argument("--quiet", action="store_true", help="print nothing but errors")
    rec.set_defaults(func=_cmd_reconstruct)

    from .cli_tools import add_parsers

    add_parsers(sub)

    info = sub.add_parser("info", help="versions, devices and the kernel cache location")
    info.set_defaults(func=_cmd_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except SceneError as exc:
        print(f"warpspec: error: {exc}", file=sys.stderr)
        return 2
    except ReconstructionError as exc:
        print(f"warpspec: failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("warpspec: interrupted; no output was written", file=sys.stderr)
        return 130
