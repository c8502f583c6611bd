"""The ``warpspec`` command line: a thin layer over the Python API.

Exit statuses: 0 done; 1 the run failed (a non-finite level set, no surface, a file that
cannot be written); 2 bad input (a scene field, an argument, a file; one line naming it,
before any work is done); 3 the data does not support the result (see
:mod:`warpspec.verdict`; nothing is written unless ``--keep-unsupported``); 130 and 143
interrupted by SIGINT or SIGTERM. Legal but suspicious input is reported as ``warning:`` lines,
at most three of a kind and a count of the rest.

No output may name an input (resolved paths and hard links are compared). Outputs are written
to unique temporary files next to their targets and renamed only when all of them are
complete; the temporary files are removed on every exit path, signals included, so an
interrupted or failed run leaves no partial file behind.

COLMAP models enter through their own subcommand, ``warpspec import-colmap``, which writes a
scene file for ``warpspec reconstruct``: the scene file stays the one input of the solver, the
import's options and warnings (lens distortion, dropped points) are dealt with once, and the
scene can be inspected and edited (a domain box, fewer points) before a run.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import gc
import json
import math
import os
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from ._atomic import (
    WRITTEN,
    StagedOutputs,
    Terminated,
    WriteError,
    atomic_write,
    check_paths,
    install_signal_cleanup,
    remove_live_temps,
    restore_signals,
)
from ._cli_common import (
    add_option,
    finite,
    input_file,
    json_safe,
    non_negative,
    non_negative_int,
    output_path,
    positive,
)
from .errors import InputError, ReconstructionError, SceneError

__all__ = ["atomic_write", "build_parser", "main", "write_mesh", "write_metrics"]

MESH_FORMATS = (".ply", ".obj", ".stl", ".glb", ".off")
METRIC_FORMATS = (".csv", ".json")
PICTURE_FORMATS = (".png", ".pdf", ".svg")
REPORT_FORMATS = (".json",)
SCENE_FORMATS = (".json",)

_REJECTED_SHOWN = 5
"""Rejected highlights named in the summary; the rest are counted (``Result.rejected`` and
``--report`` have all)."""

# Names of Python options in the API's messages and the flags that set them.
_FLAGS = {
    "alpha": "--alpha",
    "bulge": "--bulge",
    "start": "--start",
    "bulge_cap": "--bulge-cap",
    "reinit_every": "--reinit-every",
    "resolution": "--resolution",
    "iterations": "--iterations",
    "device": "--device",
    "resume": "--resume",
}


def _version() -> str:
    from . import __version__

    return __version__


# --------------------------------------------------------------------------------------------
# Writing outputs




EXIT_OK = 0
EXIT_FAILED = 1
EXIT_INPUT = 2
EXIT_UNSUPPORTED = 3
EXIT_INTERRUPTED = 130  # SIGINT (Ctrl-C)
EXIT_TERMINATED = 143  # SIGTERM


def _metrics_writer(history: list[dict], suffix: str) -> Callable[[Path], None]:
    def write(tmp: Path) -> None:
        if suffix == ".json":
            tmp.write_text(json.dumps(json_safe(history), indent=1) + "\n")
        else:
            with open(tmp, "w", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=list(history[0]))
                writer.writeheader()
                writer.writerows(history)

    return write


def _run_report(result, *, scene_path: Path, mesh_path: Path | None, faces: int,
               fit_report=None, seconds: float) -> dict:
    """The record of one reconstruction that ``--report`` writes (JSON-ready).

    Args:
        result: The :class:`~warpspec.solver.Result`.
        scene_path: The scene file read.
        mesh_path: The mesh written, or ``None`` when none was (the data does not support it).
        faces: Triangles in the mesh (after any crop).
        fit_report: The start's :class:`~warpspec.implicit.FitReport`, when it was fitted.
        seconds: Wall time from the set-up to the end.
    """
    from dataclasses import asdict

    start = None if fit_report is None else {
        "guess": fit_report.guess, "shape": fit_report.shape, "prior": fit_report.prior}
    last = result.history[-1] if result.history else {}
    return json_safe({
        "scene": str(scene_path),
        "mesh": None if mesh_path is None else str(mesh_path),
        "faces": int(faces),
        "verdict": None if result.verdict is None else asdict(result.verdict),
        "rejected": list(result.rejected),
        "start": start,
        "grid": {"shape": [int(n) for n in result.grid.shape],
                 "spacing": float(result.grid.spacing),
                 "origin": [float(v) for v in result.grid.origin]},
        "iterations": last.get("iteration"),
        "missed_rays": last.get("misses"),
        "seconds": float(seconds),
    })


def _json_writer(record: dict) -> Callable[[Path], None]:
    def write(tmp: Path) -> None:
        tmp.write_text(json.dumps(record, indent=1) + "\n")

    return write


def write_metrics(path: Path, history: list[dict]) -> None:
    """Write the per-iteration measures as CSV or JSON (by the file's extension), atomically."""
    path = Path(path)
    atomic_write(path, _metrics_writer(history, path.suffix.lower()))


def _mesh_writer(mesh, suffix: str, support=None) -> Callable[[Path], None]:
    """Write ``mesh`` (a Trimesh, or anything with vertices and faces for PLY) as ``suffix``.

    PLY carries ``support`` (per vertex, voxel widths to the nearest constraint) when given.
    """
    if suffix == ".ply":  # written directly: a run that writes PLY never imports trimesh
        from .mesh import write_ply

        extra = None if support is None else {"support": support}
        return lambda tmp: write_ply(tmp, mesh.vertices, mesh.faces, vertex_properties=extra)
    if not hasattr(mesh, "export"):
        mesh = mesh.mesh  # a Result: its Trimesh
    return lambda tmp: mesh.export(tmp, file_type=suffix[1:])


def write_mesh(path: Path, mesh) -> None:
    """Export a mesh in the format its extension names, atomically."""
    path = Path(path)
    atomic_write(path, _mesh_writer(mesh, path.suffix.lower()))


# --------------------------------------------------------------------------------------------
# Checking arguments



def _flag_message(exc: InputError) -> InputError:
    """Name the command-line flag instead of the Python option in an API message."""
    text = str(exc)
    name, sep, rest = text.partition(":")
    if sep and name in _FLAGS:
        return type(exc)(f"{_FLAGS[name]}:{rest}")
    return exc


# --------------------------------------------------------------------------------------------
# Progress and messages


class _Progress:
    """What a run is doing, on stderr: one line per set-up stage and a bar over iterations.

    Nothing is shown when quiet or not on a terminal. The bar (tqdm) appears only once the
    iterations have lasted a second.
    """

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bar = None
        self.first = None
        self.last = 0
        self._began: dict[str, float] = {}

    def stage(self, name: str, detail: str = "") -> None:
        """Announce that the stage ``name`` begins (``detail`` says what it does)."""
        self._began[name] = time.perf_counter()
        if self.enabled:
            _say(f"{name}: {detail}" if detail else f"{name} ...")

    def detail(self, text: str) -> None:
        """Say what the current stage is doing now."""
        if self.enabled:
            _say(f"  {text}")

    def done(self, name: str) -> None:
        """Say how long the stage ``name`` took."""
        began = self._began.pop(name, None)
        if self.enabled and began is not None:
            _say(f"{name}: done in {time.perf_counter() - began:.1f} s")

    def iterations(self, total: int) -> None:
        """Show the bar over ``total`` iterations."""
        if self.enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="it", file=sys.stderr, leave=True, delay=1.0,
                            dynamic_ncols=True)

    def __call__(self, m: dict) -> None:
        if self.bar is None:
            return
        if self.first is None:
            self.first = m["iteration"]
            self.last = m["iteration"]
        self.bar.update(m["iteration"] - self.last)
        self.last = m["iteration"]
        self.bar.set_postfix({"normal": _fmt(m["normal_error"], ".3g"),
                              "point": _fmt(m["point_error"], ".3g") + "h",
                              "misses": m["misses"]}, refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _setup_detail(start: str, resolution: int | None, resume: Path | None) -> str:
    """What the set-up does, in a few words: the start and the grids it is solved on."""
    from .implicit import level_ladder
    from .options import DEFAULTS

    if resume is not None:
        return f"the level set saved in {resume}"
    resolution = DEFAULTS["resolution"] if resolution is None else resolution
    if start == "implicit":
        grids = " ... ".join(str(n) for n in level_ladder(resolution))
        return (f"the implicit start: a quadric, refined on grids {grids} where it does "
                "not fit the data")
    return f"the {start} start on a {resolution}-cell grid"


def _say(text: str) -> None:
    print(f"warpspec: {text}", file=sys.stderr)


@contextlib.contextmanager
def _warnings_as_lines(quiet: bool):
    """Show each warning at once as one ``warpspec: warning: ...`` line (none when quiet)."""
    seen: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            _say(f"warning: {text}")

    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore")
        # NumPy's floating-point warnings say nothing a user can act on: the checks that
        # follow them (finite values, a surface) report the problem in the field's words.
        warnings.filterwarnings("ignore", category=RuntimeWarning,
                                message=r"(overflow|underflow|invalid value|divide by zero)")
        warnings.showwarning = show
        yield


def _constraint_normals(scene, hits):
    """The normals the reflection law demands at the ray intersections (NaN where missed)."""
    import numpy as np

    if hits is None or scene.num_specularities == 0:
        return None
    hits = np.asarray(hits, dtype=np.float64)
    ok = np.all(np.isfinite(hits), axis=1)
    origins, dirs = scene.rays()
    where = np.where(ok[:, None], hits, origins + dirs)  # any finite stand-in for a miss
    normals = scene.normals(where)
    normals[~ok] = np.nan
    return normals


def _fmt(value: float, spec: str) -> str:
    return "n/a" if not math.isfinite(value) else format(value, spec)


# --------------------------------------------------------------------------------------------
# Subcommands


def _check_scene(scene) -> None:
    """Warn about suspicious input, at most a few lines per kind (not one line per ray)."""
    import re

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene.check()
    groups: dict[str, list[str]] = {}
    for w in caught:
        text = " ".join(str(w.message).split())
        # One kind: the message with its indices and numbers taken out.
        kind = re.sub(r"\[[^\]]*\]|-?\d[\d.e+-]*", "#", text)
        groups.setdefault(kind, []).append(text)
    for texts in groups.values():
        for text in texts[:_WARNINGS_PER_KIND]:
            warnings.warn(text, stacklevel=1)
        if len(texts) > _WARNINGS_PER_KIND:
            field = texts[0].split(":", 1)[0]
            field = re.sub(r"\[\d+\]", "[...]", field)
            warnings.warn(f"{field}: {len(texts) - _WARNINGS_PER_KIND} more like the above "
                          f"({len(texts)} in all)", stacklevel=1)


_WARNINGS_PER_KIND = 3


def _cmd_reconstruct(args: argparse.Namespace) -> int:
    # Every argument is checked before the scene is read, and the scene before any work.
    out = output_path(args.output, MESH_FORMATS, "--output")
    metrics = output_path(args.metrics, METRIC_FORMATS, "--metrics") if args.metrics else None
    save_phi = output_path(args.save_phi, (".npz",), "--save-phi") if args.save_phi else None
    render = output_path(args.render, PICTURE_FORMATS, "--render") if args.render else None
    plot = output_path(args.plot, PICTURE_FORMATS, "--plot") if args.plot else None
    report = output_path(args.report, REPORT_FORMATS, "--report") if args.report else None
    resume = input_file(args.resume, "--resume") if args.resume else None
    scene_path = input_file(args.scene, "scene")
    check_paths({"--output": out, "--metrics": metrics, "--save-phi": save_phi,
                 "--render": render, "--plot": plot, "--report": report},
                {"the scene": scene_path, "--resume": resume})
    if render is not None or plot is not None:
        from .plots import require_matplotlib

        require_matplotlib("--render" if render is not None else "--plot")
    if resume is not None and args.resolution is not None:
        warnings.warn("--resolution is ignored with --resume: the saved grid is used",
                      stacklevel=1)

    from .scene import Scene

    scene = Scene.load(scene_path)
    constraints = scene.num_points + scene.num_specularities
    if args.crop == "hull" and constraints < 3:
        raise InputError("--crop: the hull needs at least 3 constraints (points and "
                         f"specularities), the scene has {constraints}")
    if not args.quiet:
        _check_scene(scene)

    from ._runtime import resolve_device

    try:
        device = resolve_device(args.device)
        from .solver import Reconstructor

        start = time.perf_counter()
        progress = _Progress(enabled=not args.quiet and sys.stderr.isatty())
        progress.stage("set-up", _setup_detail(args.start, args.resolution, resume))
        solver = Reconstructor(
            scene,
            resolution=None if resume is not None else args.resolution,
            alpha=args.alpha,
            start=args.start,
            bulge=args.bulge,
            bulge_cap=args.bulge_cap,
            device=device,
            reinit_every=args.reinit_every,
            resume=resume,
            progress=progress.detail,
        )
    except InputError as exc:
        raise _flag_message(exc) from None

    progress.done("set-up")
    iterations = solver.default_iterations if args.iterations is None else args.iterations
    progress.iterations(iterations)
    measure_every = args.measure_every
    if measure_every is None:
        measure_every = 1 if (metrics or plot) else (10 if progress.bar is not None else 0)
    try:
        solver.run(iterations, measure_every=measure_every, callback=progress)
    finally:
        progress.close()
    progress.stage("meshing", "the zero set's triangles, the support map and the verdict")
    # the hull is the data's seen along its normal: what lies behind the data goes first
    result = solver.result(crop=args.crop in ("auto", "hull"))
    progress.done("meshing")
    verdict = result.verdict

    def record(mesh_path: Path | None, faces: int) -> Callable[[Path], None]:
        """The writer of the ``--report`` file (the mesh written, or ``None``)."""
        return _json_writer(_run_report(result, scene_path=scene_path, mesh_path=mesh_path,
                                        faces=faces, fit_report=solver.fit_report,
                                        seconds=time.perf_counter() - start))

    if not verdict.supported and not args.keep_unsupported:
        written = ""
        if report is not None:
            atomic_write(report, record(None, len(result.faces)))
            written = f" but the report {report}"
        _say(f"{verdict.summary()}; nothing was written{written} (--keep-unsupported writes "
             "the outputs anyway)")
        return EXIT_UNSUPPORTED

    mesh = result  # its vertices and faces; result.mesh (trimesh) only where one is needed
    support = result.support
    if args.crop == "hull":
        from .geometry import crop_to_hull

        try:
            mesh = crop_to_hull(result.mesh, result.constraint_anchors(scene))
        except (InputError, ReconstructionError) as exc:
            raise ReconstructionError(f"--crop hull: {exc}") from None
        from .verdict import support_distance

        support = support_distance(mesh.vertices, result.constraint_anchors(scene),
                                   result.grid.spacing)
    elif args.crop == "support":
        from types import SimpleNamespace

        from .mesh import crop_to_support
        from .verdict import SUPPORT_RADIUS

        try:
            vertices, faces, support = crop_to_support(result.vertices, result.faces,
                                                       result.support, SUPPORT_RADIUS)
        except ReconstructionError as exc:
            raise ReconstructionError(f"--crop support: {exc}") from None
        if out.suffix.lower() == ".ply":
            mesh = SimpleNamespace(vertices=vertices, faces=faces)
        else:
            import trimesh

            mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)

    with StagedOutputs() as outputs:
        outputs.stage(out, _mesh_writer(mesh, out.suffix.lower(), support))
        if metrics is not None:
            outputs.stage(metrics, _metrics_writer(result.history, metrics.suffix.lower()))
        if save_phi is not None:
            from .solver import write_state

            outputs.stage(save_phi, lambda tmp: write_state(tmp, result.phi, result.grid))
        if render is not None:
            from .plots import render_mesh

            shown = mesh
            if mesh is result:
                shown = result.mesh
            elif not hasattr(mesh, "export"):
                import trimesh

                shown = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
            normals = _constraint_normals(scene, result.hits)
            outputs.stage(render, lambda tmp: render_mesh(
                shown, tmp, points=scene.points,
                hits=result.hits, normals=normals,
                cameras=scene.camera_centres(),
                title=f"{Path(args.scene).name}: {len(mesh.faces)} faces"
                      f"{f' (cropped: {args.crop})' if args.crop in ('hull', 'support') else ''}"))
        if plot is not None:
            from .plots import plot_history

            outputs.stage(plot, lambda tmp: plot_history(
                result.history, tmp, title=f"{Path(args.scene).name}: convergence"))
        if report is not None:
            outputs.stage(report, record(out, len(mesh.faces)))
        outputs.commit()

    last = result.history[-1]
    if not verdict.supported:
        _say(f"warning: {verdict.summary()}; written anyway (--keep-unsupported)")
    if not args.quiet:
        if last["misses"]:
            _say(f"warning: {last['misses']} of {scene.num_specularities} specular rays miss "
                 "the final surface; their normals were not used")
        if result.rejected:
            shown = ", ".join(
                f"#{r['index']} (camera {r['camera']}, pixel {r['pixel'][0]:.1f} "
                f"{r['pixel'][1]:.1f}, {_fmt(r['residual_deg'], '.0f')} deg)"
                for r in result.rejected[:_REJECTED_SHOWN])
            more = len(result.rejected) - _REJECTED_SHOWN
            rest = f" and {more} more (--report lists all)" if more > 0 else ""
            _say(f"{len(result.rejected)} of {scene.num_specularities} highlights rejected as "
                 f"inconsistent with the others: {shown}{rest}")
        if verdict.supported:
            _say(verdict.summary())
        begun = f" (resumed from {resume})" if resume is not None else ""
        _say(
            f"wrote {out} ({len(mesh.faces)} faces) in {time.perf_counter() - start:.1f} s"
            f"{begun}: normal error {_fmt(last['normal_error'], '.4g')}, point error "
            f"{_fmt(last['point_error'], '.3g')} voxel, {last['misses']} missed rays"
        )
    return EXIT_OK


def _cmd_import_colmap(args: argparse.Namespace) -> int:
    out = output_path(args.output, SCENE_FORMATS, "--output")
    import numpy as np

    model = Path(args.model)
    check_paths({"--output": out},
                {"--highlights": Path(args.highlights) if args.highlights else None,
                 **{f"the model's {name}": model / sub / name for sub in ("", "0")
                    for name in ("cameras.txt", "images.txt", "points3D.txt", "cameras.bin",
                                 "images.bin", "points3D.bin")}})
    from .colmap import import_colmap, parse_light

    light = parse_light(args.light, field="--light") if args.light is not None else None
    domain = None
    if args.domain is not None:
        v = args.domain
        domain = (v[:3], v[3:])
    imported = import_colmap(
        args.model, args.highlights, light=light, points=args.points,
        max_points=args.max_points, domain=domain, pixel_convention=args.pixel_convention,
    )
    scene = imported.scene
    data = scene.to_dict()
    data["_source"] = {
        "colmap_model": str(Path(args.model).resolve()),
        "highlights": None if args.highlights is None else str(Path(args.highlights).resolve()),
        "pixel_convention": args.pixel_convention,
    }
    data["_images"] = list(imported.image_names)
    data["_point_ids"] = list(imported.point_ids)
    text = json.dumps(data, indent=1, allow_nan=False) + "\n"
    with StagedOutputs() as outputs:
        outputs.stage(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
        outputs.commit()
    if not args.quiet:
        _check_scene(scene)
        lo, hi = scene.bounds()
        where = "given" if args.domain is not None else "from the rays and points"
        _say(f"wrote {out}: {scene.num_cameras} cameras, {scene.num_specularities} "
             f"specularities, {scene.num_points} points ({imported.model_format} model "
             f"{imported.model_dir}); domain {where}: min {np.round(lo, 4).tolist()} max "
             f"{np.round(hi, 4).tolist()}")
    return 0


def _model_beside(images: Sequence[str]) -> Path | None:
    """COLMAP's layout: the model of ``DIR/images`` in ``DIR/sparse/0`` or ``DIR/sparse``.

    Only for one folder of photographs, and only when exactly one such model is there.
    """
    from .colmap import find_model

    folders = [Path(p) for p in images if Path(p).is_dir()]
    if len(folders) != 1 or len(images) != 1:
        return None
    try:
        return find_model(folders[0].resolve().parent / "sparse")[0]
    except InputError:
        return None


def _cmd_detect(args: argparse.Namespace) -> int:
    import io

    from .detect import detect_highlights, find_images, model_points, read_image

    out = output_path(args.output, (".csv",), "--output")
    photos = find_images(args.images)
    check_paths({"--output": out}, {f"photograph {name}": path for name, path in photos})
    model = args.model
    if args.sfm is not None:
        if model is not None:
            raise SceneError("--sfm: give either --model (an existing COLMAP model) or --sfm "
                             "(make one), not both")
        folders = [p for p in args.images if Path(p).is_dir()]
        if len(folders) != 1 or len(args.images) != 1:
            raise SceneError("--sfm: give exactly one folder of photographs")
        from .photos import run_sfm

        model = run_sfm(folders[0], args.sfm)
        if not args.quiet:
            _say(f"structure from motion: model in {model}")
    if model is None and not args.no_model:
        model = _model_beside(args.images)
        if model is not None and not args.quiet:
            _say(f"using the COLMAP model beside the photographs: {model} (--no-model: none)")
    observed = None if model is None else model_points(model)
    by_base: dict[str, list[str]] = {}
    if observed is not None:
        for name in observed:
            by_base.setdefault(Path(name).name, []).append(name)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["image", "u", "v", "peak", "size", "score"])
    found = rejected = 0
    for name, path in photos:
        if observed is not None and name not in observed:
            match = by_base.get(Path(name).name, [])
            if len(match) == 1:
                name = match[0]
        image = read_image(path)
        options = {"min_peak": args.min_peak, "min_contrast": args.min_contrast,
                   "radius": args.radius}
        rows = detect_highlights(image, **options)
        if observed is not None:
            kept = detect_highlights(image, exclude=observed.get(name),
                                     exclude_radius=args.exclude_radius, **options)
            rejected += len(rows) - len(kept)
            rows = kept
        for u, v, peak, size, score in rows:
            writer.writerow([name, f"{u:.4f}", f"{v:.4f}", f"{peak:.4f}", int(size),
                             f"{score:.4f}"])
        found += len(rows)
    text = buffer.getvalue()
    with StagedOutputs() as outputs:
        outputs.stage(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
        outputs.commit()
    if not args.quiet:
        extra = (f", {rejected} bright spots dropped as tracked texture"
                 if observed is not None else "")
        _say(f"wrote {out}: {found} highlights in {len(photos)} photographs{extra}")
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
    try:
        from matplotlib import __version__ as mpl
    except ImportError:
        mpl = "not installed (pip install 'warpspec[plot]' for --render and --plot)"
    print(f"matplotlib {mpl}")
    return 0


# --------------------------------------------------------------------------------------------
# Argument types and the parser







def _points_choice(text: str) -> str | list[int]:
    if text in ("all", "none", "auto"):
        return text
    try:
        return [int(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'auto', 'all', 'none' or POINT3D_IDs like 12,40,41, got {text!r}"
        ) from None


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: ``prog: error: message (see --help)``.

    ``epilog_factory`` makes the epilog only when the help is shown (the list of built-in
    scenes imports trimesh and SciPy, which a reconstruction does not otherwise need).
    """

    def __init__(self, *args, epilog_factory: Callable[[], str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.epilog_factory = epilog_factory

    def format_help(self) -> str:
        if self.epilog_factory is not None:
            self.epilog, self.epilog_factory = self.epilog_factory(), None
        return super().format_help()

    def error(self, message: str):
        text = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {text} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``warpspec`` command."""
    parser = _Parser(
        prog="warpspec",
        description="Reconstruct shiny surfaces from sparse points and specular highlights.",
    )
    parser.add_argument("--version", action="version", version=f"warpspec {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rec = sub.add_parser("reconstruct", help="reconstruct a surface mesh from a scene file",
                         description="Reconstruct a surface mesh from a scene file.")
    rec.add_argument("scene", help="scene file (JSON, version 1); make one from a COLMAP "
                                   "model with 'warpspec import-colmap'")
    rec.add_argument("-o", "--output", required=True,
                     help=f"mesh to write; format by extension ({', '.join(MESH_FORMATS)})")
    for name in ("resolution", "iterations", "alpha", "start", "bulge", "bulge_cap",
                 "reinit_every"):
        add_option(rec, name, **({"default": None} if name == "resolution" else {}))
    rec.add_argument("--device", default=None,
                     help="Warp device: cpu, cuda, cuda:0 (default: CUDA if present)")
    rec.add_argument("--metrics", default=None,
                     help="write the per-iteration measures (.csv or .json)")
    add_option(rec, "measure_every", default=None, metavar="N",
               help="reduce the measures every N iterations, 0 only at the start and the end; "
                    "each costs a reduction and a device synchronisation",
               shown="1 with --metrics or --plot, else 10 for the progress bar, 0 when there "
                     "is none")
    rec.add_argument("--save-phi", default=None, help="keep the level set and its grid (.npz)")
    rec.add_argument("--resume", default=None, help="continue from a level set saved with "
                                                    "--save-phi (its grid is used)")
    rec.add_argument("--crop", default="auto", choices=["auto", "none", "hull", "support"],
                     help="auto (default): crop an open surface that bends round (its "
                          "normals turn past 120 degrees) to where the data reaches (the "
                          "hull of the rays' hits and the points, unwrapped round the "
                          "surface's axis); drop what lies behind a gentler one seen from "
                          "one side; keep others whole; none: the whole zero set; hull: of "
                          "what auto keeps, the faces inside the hull of the constraints; "
                          "support: the faces within 3 voxels of a constraint "
                          "(a ray's hit or a point)")
    rec.add_argument("--report", default=None, metavar="FILE.json",
                     help="write the run's record: the verdict and its figures, every "
                          "highlight rejected (index, camera, pixel, residual), the start's "
                          "shape, the grid, the time (written also when the data does not "
                          "support the result)")
    rec.add_argument("--keep-unsupported", action="store_true",
                     help="write the outputs even when the data does not support the result "
                          "(most rays miss, the normals or the points disagree with the "
                          "surface); without it such a run writes nothing but --report and "
                          "exits with 3")
    rec.add_argument("--render", default=None, metavar="FILE.png",
                     help="draw views of the mesh with the constraint points and normals "
                          "(needs matplotlib)")
    rec.add_argument("--plot", default=None, metavar="FILE.png",
                     help="draw the convergence curves (needs matplotlib)")
    rec.add_argument("--quiet", action="store_true", help="print nothing but errors")
    rec.set_defaults(func=_cmd_reconstruct)

    imp = sub.add_parser(
        "import-colmap", help="make a scene file from a COLMAP model and highlights",
        description="Make a scene file from a COLMAP model (cameras, images, points3D as .txt "
                    "or .bin) and a CSV of highlights (image,u,v rows, as 'warpspec detect' "
                    "writes them; by default in COLMAP's pixel convention, where the centre of "
                    "the top-left pixel is (0.5, 0.5)). Every registered image becomes a "
                    "camera, in IMAGE_ID order; highlights are undistorted. By default the "
                    "points are those of the object, near where the highlight rays meet (not "
                    "the table and walls), and the domain is sized so that every ray enters.")
    imp.add_argument("model", help="folder of the COLMAP model, or a sparse/ folder holding 0/")
    imp.add_argument("--highlights", default=None, metavar="CSV",
                     help="CSV of highlights: image name, u, v, then any columns (header "
                          "optional)")
    imp.add_argument("--light", default=None, metavar="SPEC",
                     help="the light, in the model's frame: camera, directional:X,Y,Z (toward "
                          "the light), point:X,Y,Z, or a JSON object")
    imp.add_argument("-o", "--output", required=True, help="scene file to write (.json)")
    imp.add_argument("--points", type=_points_choice, default="auto",
                     help="3D points to use as constraints: auto (the object's: near where "
                          "the highlight rays meet, off the background planes), all, none, or "
                          "POINT3D_IDs 12,40,41 (default auto)")
    imp.add_argument("--max-points", type=non_negative_int, default=None,
                     help="keep at most this many points, those of least reprojection error")
    imp.add_argument("--domain", type=finite, nargs=6, default=None,
                     metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
                     help="box to reconstruct in; points outside it are dropped (default: "
                          "sized from the rays and the object's points)")
    imp.add_argument("--pixel-convention", choices=["colmap", "index"], default="colmap",
                     help="colmap: top-left pixel centre at (0.5, 0.5) (default); index: at "
                          "(0, 0), as OpenCV and NumPy row/column indices")
    imp.add_argument("--quiet", action="store_true", help="print nothing but errors")
    imp.set_defaults(func=_cmd_import_colmap)

    det = sub.add_parser(
        "detect", help="find the specular highlights in photographs (CSV for import-colmap)",
        description="Find specular highlights (small, near-saturated, compact spots much "
                    "brighter than their surroundings) in photographs, at subpixel precision, "
                    "and write one row per highlight: image,u,v,peak,size,score, in COLMAP's "
                    "pixel convention (the centre of the top-left pixel is (0.5, 0.5)); the "
                    "image is named as COLMAP names it, relative to the folder given.")
    det.add_argument("images", nargs="+", metavar="IMAGE_OR_FOLDER",
                     help="photographs (PNG, JPEG, TIFF; 8 or 16 bits) or folders of them")
    det.add_argument("-o", "--output", required=True, help="CSV of highlights to write (.csv)")
    det.add_argument("--model", default=None, metavar="SPARSE_DIR",
                     help="COLMAP model of the photographs: a bright spot within "
                          "--exclude-radius of a 3D point seen in that image is tracked "
                          "texture, not a highlight (default: the model beside a folder of "
                          "photographs, DIR/sparse/0 or DIR/sparse for DIR/images, if any)")
    det.add_argument("--no-model", action="store_true",
                     help="do not look for a COLMAP model beside the photographs")
    det.add_argument("--sfm", default=None, metavar="WORKSPACE",
                     help="first run COLMAP's structure from motion (pycolmap: pip install "
                          "'warpspec[photos]') on the folder of photographs, into "
                          "WORKSPACE/sparse/0, and use that model as --model")
    det.add_argument("--min-peak", type=positive, default=0.8,
                     help="least brightness of a highlight, fraction of full scale (default "
                          "0.8)")
    det.add_argument("--min-contrast", type=positive, default=0.3,
                     help="least height above the local background, fraction of full scale "
                          "(default 0.3)")
    det.add_argument("--radius", type=positive, default=None, metavar="PX",
                     help="largest highlight radius in pixels (default 2%% of the smaller "
                          "image side, at least 4)")
    det.add_argument("--exclude-radius", type=non_negative, default=3.0, metavar="PX",
                     help="with --model: distance in pixels within which a tracked point "
                          "makes a bright spot texture (default 3)")
    det.add_argument("--quiet", action="store_true", help="print nothing but errors")
    det.set_defaults(func=_cmd_detect)

    from .cli_tools import add_parsers

    add_parsers(sub)

    info = sub.add_parser("info", help="versions, devices and the kernel cache location")
    info.set_defaults(func=_cmd_info, quiet=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Statuses: 0 done; 1 the run failed (a non-finite level set, no surface, a file that
    cannot be written); 2 bad input (one line naming the field); 3 the data does not support
    the result (nothing written; ``--keep-unsupported`` writes it and exits 0); 130 and 143
    interrupted by SIGINT and SIGTERM (temporary files removed, no output half-written).

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a bad argument (already reported)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    previous = install_signal_cleanup()
    WRITTEN.clear()
    try:
        return _run(args)
    finally:
        restore_signals(previous)


def _run(args: argparse.Namespace) -> int:
    """Run one subcommand and turn its outcome into the exit status."""
    try:
        with _warnings_as_lines(getattr(args, "quiet", False)):
            return args.func(args)
    except InputError as exc:
        _say(f"error: {' '.join(str(exc).split())}")
        return EXIT_INPUT
    except ReconstructionError as exc:
        _say(f"failed: {' '.join(str(exc).split())}")
        return EXIT_FAILED
    except KeyboardInterrupt as exc:
        remove_live_temps()
        terminated = isinstance(exc, Terminated)
        done = (f"only {', '.join(map(str, WRITTEN))} had been written" if WRITTEN else
                "no output was written")
        _say(f"{'terminated' if terminated else 'interrupted'}; {done}")
        return EXIT_TERMINATED if terminated else EXIT_INTERRUPTED
    except MemoryError:
        remove_live_temps()
        _say("failed: out of memory; lower the resolution or use a smaller input")
        return EXIT_FAILED
    except WriteError as exc:
        _say(f"failed: {exc}")
        return EXIT_FAILED
    except OSError as exc:
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        _say(f"failed:{where} {exc.strerror or exc}")
        return EXIT_FAILED
    except Exception as exc:  # a bug: one line, and the traceback only when asked for
        remove_live_temps()
        if os.environ.get("WARPSPEC_DEBUG"):
            traceback.print_exc()
        _say(f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())[:300]} "
             "(this is a bug in warpspec; set WARPSPEC_DEBUG=1 for the traceback)")
        return EXIT_FAILED


def entry() -> NoReturn:
    """The ``warpspec`` program: :func:`main`, then exit without a final garbage collection.

    At exit Python collects every object it tracks; with Warp's builtins, SciPy (through
    trimesh) and scikit-image loaded that takes about 0.4 s, for memory the OS reclaims
    anyway. Freezing the collector first skips it. Outputs are closed by then, and objects
    that reference-counting frees still are.
    """
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    gc.freeze()
    sys.exit(status)

