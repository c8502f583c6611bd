"""Subcommands for synthetic scenes and evaluation (``warpspec synth``, ``warpspec evaluate``).

Both report bad input as :class:`warpspec.errors.InputError` with a one-line message that names
the flag; ``warpspec.cli.main`` turns it into exit status 2. No output may name an input, and
files are written through unique temporary files in the same folder and renamed together, so
an interrupted or failed run leaves no partial file behind.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ._atomic import StagedOutputs, atomic_write, check_paths, check_size
from ._cli_common import finite, input_file, integer, json_safe, output_path
from .errors import InputError

__all__ = ["EVALUATE_DEFINITIONS", "add_parsers"]

MESH_FORMATS = (".ply", ".obj", ".stl", ".off", ".glb")
MAX_SAMPLES = 10_000_000
"""Most area samples per mesh for ``evaluate`` (each costs a closest-point query: 10^7 take
minutes and about 2 GiB)."""
MAX_MESH_BYTES = 2 * 2**30
"""Largest mesh file ``evaluate`` reads."""
MAX_JSON_BYTES = 512 * 2**20
"""Largest truth JSON file ``evaluate`` reads."""

EVALUATE_DEFINITIONS = """\
How each figure is defined:
  Both meshes are sampled uniformly by area (--samples points each, seeded, plus their
  vertices); each sample's distance to the other mesh is exact (closest point on its
  triangles, no sampling of the other side).
  completeness  distances from the samples of the TRUTH to the reconstructed MESH
                (is every part of the truth reconstructed?)
  accuracy      distances from the samples of the reconstructed MESH to the TRUTH
                (is every part of the reconstruction on the truth?)
  Each is summarised by its mean, RMS (root of the mean square), 95th percentile and max,
  in world units and in voxel widths h.
  Chamfer       the symmetric mean: (accuracy mean + completeness mean) / 2
                (not the sum, and not of squared distances)
  Hausdorff     max(accuracy max, completeness max)
  h             the voxel width of the reconstruction grid: the longest side of the scene's
                domain divided by --resolution (the solver's grid), or --spacing
  region        with --scene (or --truth-json), only samples inside the region the
                constraints cover count: the true specular points and the point constraints
                are projected onto their best-fit plane, and a sample counts when its
                projection falls inside their 2D convex hull (the paper's crop); --no-crop
                keeps every sample
  normal angle  at each true specular point x: the angle in degrees between the true
                surface normal at x and the normal of the face of MESH closest to x.
                The true specular points come from --truth-json when given (the generator's
                exact points and normals); otherwise they are where the scene's rays first
                meet the TRUTH mesh, with the normal of the TRUTH face hit (so TRUTH against
                itself gives 0; a faceted TRUTH adds its facet error).
"""


# --------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------







def _load_mesh(text: str, flag: str):
    import trimesh

    path = input_file(text, flag)
    check_size(path, MAX_MESH_BYTES, flag)
    try:
        with np.errstate(all="ignore"):
            mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        reason = " ".join(str(exc).split())[:120]
        raise InputError(f"{flag}: cannot read {text!r} as a mesh ({reason})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{flag}: {text!r} holds no triangles")
    faces = np.asarray(mesh.faces)
    if faces.min() < 0 or faces.max() >= len(mesh.vertices):
        raise InputError(f"{flag}: {text!r} has faces that index vertices out of range "
                         f"(0 to {len(mesh.vertices) - 1}, found {faces.min()} to {faces.max()})")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(f"{flag}: {text!r} has non-finite vertices")
    return mesh


def _load_truth_json(text: str, flag: str) -> dict:
    path = input_file(text, flag)
    check_size(path, MAX_JSON_BYTES, flag)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError,
            ValueError) as exc:
        reason = " ".join(str(exc).split())[:120]
        raise InputError(f"{flag}: {text!r} is not readable JSON ({reason})") from None
    if not isinstance(data, dict):
        raise InputError(f"{flag}: {text!r} must hold a JSON object")
    out = {}
    for key, required in (("truth_points", True), ("truth_normals", True), ("points", False),
                          ("outliers", False)):
        if key not in data:
            if required:
                raise InputError(f"{flag}: {text!r} has no field {key!r} (write it with "
                                 "'warpspec synth --truth-json')")
            continue
        try:
            arr = np.asarray(data[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{flag}: field {key!r} of {text!r} is not numeric") from None
        if key == "outliers":
            flat = arr.reshape(-1)
            if not np.all(np.isfinite(flat)) or np.any(flat != np.round(flat)):
                raise InputError(f"{flag}: field 'outliers' of {text!r} must hold integer "
                                 "indices")
            out[key] = flat.astype(np.int64)
            continue
        if arr.size and (arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr))):
            raise InputError(f"{flag}: field {key!r} of {text!r} must be finite (N, 3) rows")
        out[key] = arr.reshape(-1, 3)
    if out["truth_points"].shape != out["truth_normals"].shape:
        raise InputError(f"{flag}: 'truth_points' and 'truth_normals' of {text!r} differ in "
                         "length")
    n = len(out["truth_points"])
    outliers = out.get("outliers")
    if outliers is not None and len(outliers) and (outliers.min() < 0 or outliers.max() >= n):
        raise InputError(f"{flag}: field 'outliers' of {text!r} holds indices out of range "
                         f"(0 to {n - 1}, found {outliers.min()} to {outliers.max()})")
    return out


# --------------------------------------------------------------------------------------------
# warpspec synth
# --------------------------------------------------------------------------------------------


def _cmd_synth(args: argparse.Namespace) -> int:
    from .synthetic import make_scene, scene_names

    if args.name not in scene_names():
        raise InputError(f"NAME: unknown scene {args.name!r}; expected one of "
                         f"{', '.join(scene_names())}")
    if args.output is None and args.photos is None:
        raise InputError("--output: required (the scene file to write, .json) unless --photos "
                         "DIR is given")
    out = output_path(args.output, (".json",), "--output") if args.output else None
    photos = _photos_folder(args.photos) if args.photos else None
    truth = output_path(args.truth, MESH_FORMATS, "--truth") if args.truth else None
    truth_json = (output_path(args.truth_json, (".json",), "--truth-json")
                  if args.truth_json else None)
    if args.noise < 0:
        raise InputError(f"--noise: must be a non-negative number of pixels, got {args.noise:g}")
    if not 0 <= args.outliers <= 1:
        raise InputError(f"--outliers: must be a fraction in [0, 1], got {args.outliers:g}")
    if args.point_noise < 0:
        raise InputError(f"--point-noise: must be a non-negative number of voxels, got "
                         f"{args.point_noise:g}")
    if args.seed < 0:
        raise InputError(f"--seed: must be a non-negative integer, got {args.seed}")
    check_paths({"--output": out, "--truth": truth, "--truth-json": truth_json})

    options = {}
    if args.highlights is not None:
        if args.name != "freeform":
            raise InputError(f"--highlights: only the 'freeform' scene takes it, not "
                             f"{args.name!r}")
        options["highlights"] = args.highlights
    try:
        synthetic = make_scene(args.name, noise=args.noise, outliers=args.outliers,
                               seed=args.seed, point_noise=args.point_noise, **options)
    except InputError as exc:
        if str(exc).startswith("highlights:"):
            raise InputError(f"--{exc}") from None
        raise
    written = []
    # All or nothing: a scene without its truth is worse than no scene.
    with StagedOutputs() as outputs:
        if out is not None:
            outputs.stage(out, lambda tmp: synthetic.to_json(tmp))
            written.append(str(out))
        if truth is not None:
            mesh = synthetic.truth_mesh()
            outputs.stage(truth, lambda tmp: mesh.export(tmp,
                                                         file_type=truth.suffix.lower()[1:]))
            written.append(f"{truth} ({len(mesh.faces)} faces)")
        if truth_json is not None:
            text = json.dumps(synthetic.truth_dict(), indent=1) + "\n"
            outputs.stage(truth_json, lambda tmp: tmp.write_text(text))
            written.append(str(truth_json))
        outputs.commit()
    if photos is not None:
        from .photos import render_photos

        shot = render_photos(synthetic, photos, scale=PHOTO_SCALE, seed=args.seed)
        written.append(f"{photos} ({len(shot.image_names)} photographs {shot.width}x"
                       f"{shot.height}, COLMAP model in sparse/0, highlights_true.csv)")
    if not args.quiet:
        print(f"{args.name}: {len(synthetic.truth_points)} specularities "
              f"({int(synthetic.outlier_mask.sum())} outliers, noise {args.noise:g} px), "
              f"{len(synthetic.cameras)} cameras, {len(synthetic.points)} points"
              f"{f' (noise {args.point_noise:g} voxel)' if args.point_noise else ''}, "
              f"{_light_kind(synthetic.scene_dict)} -> {', '.join(written)}",
              file=sys.stderr)
    return 0


def _light_kind(scene_dict: dict) -> str:
    """``"camera light"``, or ``"per-camera directional lights"`` when each camera has one."""
    if "light" in scene_dict:
        return f"{scene_dict['light']['type']} light"
    kinds = sorted({c["light"]["type"] for c in scene_dict["cameras"] if "light" in c})
    return f"per-camera {'/'.join(kinds)} lights"


PHOTO_SCALE = 0.5
"""Size of ``synth --photos`` photographs relative to the scenes' 640x480 cameras."""


def _photos_folder(text: str) -> Path:
    """The folder for ``--photos``: new, or empty, or one it wrote before (images/, sparse/)."""
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise InputError(f"--photos: {text!r} is a file, expected a folder")
    if p.is_dir():
        extra = sorted(x.name for x in p.iterdir()
                       if x.name not in ("images", "sparse", "highlights_true.csv", "truth.ply",
                                         "scene_true.json"))
        if extra:
            raise InputError(f"--photos: {text!r} holds other files ({', '.join(extra[:3])}); "
                             "give a new or empty folder")
    elif not p.parent.is_dir():
        raise InputError(f"--photos: the folder {str(p.parent)!r} does not exist")
    return p


def _scene_list() -> str:
    from .synthetic import FREEFORM_HIGHLIGHTS, SCENES

    lines = []
    for name, make in SCENES.items():
        doc = (make.__doc__ or "").strip().splitlines()
        lines.append(f"  {name:<17} {doc[0] if doc else ''}")
    lines.append(f"freeform takes --highlights N (default {FREEFORM_HIGHLIGHTS})")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# warpspec evaluate
# --------------------------------------------------------------------------------------------


def _true_specular_points(scene, truth) -> tuple[np.ndarray, np.ndarray]:
    """Where the scene's rays first meet the truth mesh, and the normals of the faces hit.

    Face normals keep the evaluation exact for the truth against itself; the exact normals of
    a smooth truth come with ``--truth-json``.
    """
    from .evaluate import ray_mesh_intersect

    origins, dirs = scene.rays()
    hits, faces = ray_mesh_intersect(truth, origins, dirs)
    ok = faces >= 0
    return hits[ok], np.asarray(truth.face_normals, dtype=np.float64)[faces[ok]]


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate, truth_region
    from .grid import Grid

    json_out = output_path(args.json, (".json",), "--json") if args.json else None
    check_paths({"--json": json_out},
                {"MESH": input_file(args.mesh, "MESH"),
                 "--truth": input_file(args.truth, "--truth"),
                 "--scene": input_file(args.scene, "--scene") if args.scene else None,
                 "--truth-json": (input_file(args.truth_json, "--truth-json")
                                  if args.truth_json else None)})
    if not 100 <= args.samples <= MAX_SAMPLES:
        raise InputError(f"--samples: must be between 100 and {MAX_SAMPLES}, got "
                         f"{args.samples}")
    if args.seed < 0:
        raise InputError(f"--seed: must be a non-negative integer, got {args.seed}")
    if args.spacing is not None and args.spacing <= 0:
        raise InputError(f"--spacing: must be a positive length, got {args.spacing:g}")
    if args.resolution is not None and args.resolution < 2:
        raise InputError(f"--resolution: must be at least 2 cells, got {args.resolution}")
    if args.resolution is not None and args.spacing is not None:
        raise InputError("--resolution: give either --resolution (with --scene) or --spacing")
    if args.resolution is not None and args.scene is None:
        raise InputError("--resolution: needs --scene (h is the longest side of the scene's "
                         "domain divided by N); without a scene give --spacing")

    mesh = _load_mesh(args.mesh, "MESH")
    truth = _load_mesh(args.truth, "--truth")
    scene = None
    if args.scene is not None:
        from .scene import Scene

        scene = Scene.load(input_file(args.scene, "--scene"))
    known = _load_truth_json(args.truth_json, "--truth-json") if args.truth_json else None

    spacing = args.spacing
    if spacing is None and scene is not None:
        lo, hi = scene.bounds()
        spacing = Grid.from_bounds(lo, hi, resolution=args.resolution or 64).spacing

    specular = normals = None
    constraint_points = np.zeros((0, 3))
    if known is not None:
        keep = np.ones(len(known["truth_points"]), dtype=bool)
        keep[known.get("outliers", np.zeros(0, dtype=np.int64))] = False
        specular, normals = known["truth_points"][keep], known["truth_normals"][keep]
        constraint_points = known.get("points", constraint_points)
    elif scene is not None:
        specular, normals = _true_specular_points(scene, truth)
    if scene is not None:
        constraint_points = scene.points
    region = None
    if not args.no_crop and specular is not None:
        try:
            region = truth_region(specular, constraint_points)
        except InputError as exc:
            raise InputError(f"--scene: cannot crop to the constraints ({exc}); use --no-crop"
                             ) from None
    try:
        result = evaluate(mesh, truth, spacing=spacing, region=region,
                          specular_points=specular, true_normals=normals,
                          samples=args.samples, seed=args.seed)
    except InputError as exc:
        raise InputError(f"MESH: {exc}") from None

    print(f"# {args.mesh} against {args.truth}")
    if spacing:
        how = (f"--spacing {spacing:g}" if args.spacing is not None else
               f"scene domain / {args.resolution or 64}")
        print(f"voxel width h = {spacing:.6g} ({how})")
    print(result.table())
    if json_out is not None:
        data = result.to_dict()
        data.update(mesh=str(args.mesh), truth=str(args.truth), scene=args.scene,
                    resolution=(args.resolution or 64) if scene is not None and
                    args.spacing is None else None)
        if result.normal_angles is not None:
            data["normal_angle_deg"]["values"] = [float(a) for a in result.normal_angles]
        text = json.dumps(json_safe(data), indent=1) + "\n"
        atomic_write(json_out, lambda tmp: tmp.write_text(text))
    return 0


# --------------------------------------------------------------------------------------------
# Parsers
# --------------------------------------------------------------------------------------------


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register ``synth`` and ``evaluate`` on the ``warpspec`` parser."""
    synth = sub.add_parser(
        "synth",
        help="write a built-in synthetic scene with its ground truth",
        description="Write a built-in synthetic scene (scene format version 1) and, optionally, "
                    "its ground truth. The paper's scenes (octant to saddle) have a fixed "
                    "geometry and --seed drives only the pixel noise and the outliers; for the "
                    "scenes of every shape class (sphere-around to point-light) --seed also "
                    "varies the shape a little (sizes, bumps, camera jitter, which points).",
        epilog_factory=lambda: "scenes:\n" + _scene_list(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    synth.add_argument("name", metavar="NAME", help="built-in scene (listed below)")
    synth.add_argument("-o", "--output", default=None, metavar="SCENE",
                       help="scene file to write (.json); required unless --photos is given")
    synth.add_argument("--photos", default=None, metavar="DIR",
                       help="also render 320x240 photographs of the glossy object in a textured "
                            "room, with the exact COLMAP model (DIR/images, DIR/sparse/0, "
                            "DIR/highlights_true.csv, DIR/truth.ply)")
    synth.add_argument("--truth", metavar="MESH", default=None,
                       help="also write the truth mesh: the surface cut to the patch the "
                            f"highlights lie on ({', '.join(MESH_FORMATS)})")
    synth.add_argument("--truth-json", metavar="FILE", default=None,
                       help="also write the true specular points and normals, the point "
                            "constraints, the clean pixels and the outliers' indices (.json)")
    synth.add_argument("--noise", type=finite, default=0.0, metavar="PX",
                       help="standard deviation of Gaussian noise added to each highlight's "
                            "pixel, in pixels (default 0)")
    synth.add_argument("--outliers", type=finite, default=0.0, metavar="F",
                       help="fraction of highlights replaced by false ones: a pixel drawn "
                            "uniformly over the image (the paper's scenes) or one on the object "
                            "whose normal is wrong by 15 degrees or more (the shape-class "
                            "scenes); the truth JSON lists them (default 0)")
    synth.add_argument("--point-noise", type=finite, default=0.0, metavar="VOXELS",
                       help="standard deviation of Gaussian noise added to each coordinate of "
                            "the 3D points, in voxels of the default grid (the domain's longest "
                            "side / 64), as structure from motion's points carry; the truth "
                            "JSON keeps the clean ones (default 0)")
    synth.add_argument("--seed", type=integer, default=0, metavar="S",
                       help="seed of the noise and the outliers, and of the shape for the "
                            "scenes of every shape class (default 0)")
    synth.add_argument("--highlights", type=integer, default=None, metavar="N",
                       help="freeform only: number of highlights (default: the scene's, "
                            "shown below)")
    synth.add_argument("--quiet", action="store_true", help="print nothing but errors")
    synth.set_defaults(func=_cmd_synth)

    ev = sub.add_parser(
        "evaluate",
        help="score a reconstructed mesh against the truth (completeness, accuracy, normals)",
        description="Score a reconstructed mesh against the ground truth and print the figures "
                    "as a markdown table.",
        epilog=EVALUATE_DEFINITIONS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ev.add_argument("mesh", metavar="MESH", help="the reconstructed mesh (.ply, .obj, .stl, ...)")
    ev.add_argument("--truth", required=True, metavar="TRUTH", help="the truth mesh")
    ev.add_argument("--scene", default=None, metavar="SCENE",
                    help="the scene file: gives the voxel width h, the crop to the constraints "
                         "and the specular rays (whose first hits on TRUTH are taken as the "
                         "true specular points)")
    ev.add_argument("--truth-json", default=None, metavar="FILE",
                    help="exact true specular points and normals (and point constraints), as "
                         "written by 'warpspec synth --truth-json'; outliers are left out")
    ev.add_argument("--resolution", type=integer, default=None, metavar="N",
                    help="with --scene: h = longest side of the scene's domain / N, the grid "
                         "of 'warpspec reconstruct --resolution N' (default 64)")
    ev.add_argument("--spacing", type=finite, default=None, metavar="H",
                    help="give the voxel width h directly, in world units")
    ev.add_argument("--no-crop", action="store_true",
                    help="measure the whole meshes, not only the region the constraints cover")
    ev.add_argument("--samples", type=integer, default=20_000,
                    help="area-uniform samples per mesh, on top of its vertices (default 20000)")
    ev.add_argument("--seed", type=integer, default=0, help="seed of the sampling (default 0)")
    ev.add_argument("--json", default=None, metavar="FILE",
                    help="also write every figure to this file (.json)")
    ev.set_defaults(func=_cmd_evaluate)
