"""A rendered-photo bench: photographs of a glossy synthetic object with a COLMAP model.

:func:`render_photos` takes a :class:`~warpspec.synthetic.SyntheticScene` (its surface, cameras
and light) and writes what a user would have after photographing a shiny object and running
COLMAP on the pictures::

    DIR/images/view_000.png ...     8-bit RGB photographs
    DIR/sparse/0/cameras.{txt,bin}  the exact cameras (PINHOLE), text and binary
    DIR/sparse/0/images.{txt,bin}   poses and 2-D observations
    DIR/sparse/0/points3D.{txt,bin} object points and background points with their tracks
    DIR/highlights_true.csv         image,u,v of every true highlight (COLMAP's pixels)
    DIR/truth.ply                   the object's truth mesh
    DIR/scene_true.json             the synthetic scene the photographs were made from

The object (the scene's truth mesh) stands in a closed room whose floor and walls carry a
random value-noise texture (so that structure from motion would find features) and small
bright spots: some saturate like a highlight, some are only bright; every spot is a tracked
3D point of the model, as a real texture feature would be. Shading is Lambert plus a sharp
Blinn-Phong lobe on the object, with the scene's light (a flash at each camera, a lamp or the
sun; lamps and the sun cast shadows), ``ss x ss`` samples per pixel, then Gaussian sensor noise
and 8-bit rounding (values above 1 clip). Rays are Warp mesh queries
(:mod:`warpspec.kernels.render`).

Pixels follow COLMAP's convention (the centre of the top-left pixel is ``(0.5, 0.5)``). The
synthetic scenes' cameras use pixel indices at 640x480; the bench scales them by ``scale``
(``0.25``: 160x120) and shifts the principal point by half a pixel, so each highlight of the
scene appears at ``scale * (pixel + 0.5)``.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, SceneError
from .geometry import LIGHT_CODES

__all__ = ["PhotoSet", "closed_sphere", "render_photos", "run_sfm"]

@dataclass(frozen=True)
class PhotoSet:
    """What :func:`render_photos` wrote.

    Attributes:
        folder: The output folder.
        image_names: File names of the photographs (relative to ``folder / "images"``).
        width: Image width in pixels.
        height: Image height in pixels.
        highlights: True highlights, ``(M, 3)`` rows of image index, u, v (COLMAP's pixels).
        object_point_ids: ``POINT3D_ID`` of the points on the object.
        background_point_ids: ``POINT3D_ID`` of the points on the floor and walls.
        spot_point_ids: ``POINT3D_ID`` of the bright texture spots (a subset of the background).
        saturated_spot_ids: Those spots that saturate like a highlight.
        room: The room box ``(min, max)``.
    """

    folder: Path
    image_names: tuple[str, ...]
    width: int
    height: int
    highlights: np.ndarray
    object_point_ids: tuple[int, ...]
    background_point_ids: tuple[int, ...]
    spot_point_ids: tuple[int, ...]
    saturated_spot_ids: tuple[int, ...]
    room: tuple[np.ndarray, np.ndarray]


def closed_sphere(*, views: int = 24, seed: int = 0) -> Any:
    """A closed object for the bench: a sphere of radius 0.5 seen from all around.

    ``views`` cameras on a Fibonacci sphere of radius 2 around the centre ``(0, 0, 0.5)``
    (elevations from -30 to +60 degrees), each with its flash as the light, looking at a point
    within 0.15 of the centre so that the highlights fall at various pixels; six point
    constraints spread over the sphere.

    Returns:
        The :class:`~warpspec.synthetic.SyntheticScene`.
    """
    from .synthetic import CameraLight, Sphere, scene_from_path, spread_points

    centre = np.array([0.0, 0.0, 0.5])
    sphere = Sphere(centre, 0.5)
    rng = np.random.default_rng(seed)
    i = np.arange(views) + 0.5
    z = math.sin(math.radians(-30)) + (math.sin(math.radians(60)) -
                                       math.sin(math.radians(-30))) * i / views
    r = np.sqrt(1 - z * z)
    a = math.pi * (3 - math.sqrt(5)) * i
    dirs = np.column_stack([r * np.cos(a), r * np.sin(a), z])
    centres = centre + 2.0 * dirs
    targets = centre + rng.uniform(-0.15, 0.15, size=(views, 3))
    verts = np.asarray(sphere.mesh(subdivisions=3).vertices)
    pts = spread_points(verts[verts[:, 2] > 0.3], 6, start=(0.5, 0.0, 0.5))
    return scene_from_path(
        sphere, centres, light=CameraLight(), look_at_points=targets, points=pts,
        domain=(centre - 0.6, centre + 0.6), name="closed-sphere",
        mesh_options={"subdivisions": 5},
    )


# --------------------------------------------------------------------------------------------
# Geometry helpers


def _room(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The six inward-facing walls of a box: vertices, faces and vertex normals."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3)]
    centre = (lo + hi) / 2
    verts, faces, normals = [], [], []
    for quad in quads:
        base = len(verts)
        v = corners[list(quad)]
        n = np.cross(v[1] - v[0], v[2] - v[0])
        n /= np.linalg.norm(n)
        if np.dot(n, centre - v[0]) < 0:
            n = -n
        verts.extend(v)
        normals.extend([n] * 4)
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(verts), np.array(faces), np.array(normals)


def _sample_room(lo: np.ndarray, hi: np.ndarray, count: int, rng: np.random.Generator
                 ) -> np.ndarray:
    """``count`` points uniform by area on the box's walls, floor and ceiling."""
    size = hi - lo
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    side = rng.choice(6, size=count, p=areas / areas.sum())
    pts = lo + rng.uniform(size=(count, 3)) * size
    axis, upper = side // 2, side % 2
    pts[np.arange(count), axis] = np.where(upper == 1, hi[axis], lo[axis])
    return pts


def _curvature_radius(surface: Any, x: np.ndarray, scale: float) -> float:
    """Smallest radius of curvature of ``surface`` at ``x``, from its chart (finite steps)."""
    try:
        chart = surface.chart(x)
    except Exception:  # a surface without a chart: a broad guess
        return scale
    n0 = surface.normal(x[None])[0]
    eps = 1e-3 * scale
    bend = 0.0
    for uv in ((eps, 0.0), (0.0, eps)):
        p = chart(np.array(uv))
        bend = max(bend, float(np.linalg.norm(surface.normal(p[None])[0] - n0)) /
                   max(float(np.linalg.norm(p - x)), 1e-300))
    return 1.0 / bend if bend > 0 else 10.0 * scale


def _quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix, ``w >= 0``."""
    from .colmap import quaternion_from_rotation

    return quaternion_from_rotation(R)


# --------------------------------------------------------------------------------------------
# The bench


def render_photos(
    synthetic: Any,
    folder: str | os.PathLike,
    *,
    scale: float = 0.25,
    samples: int = 4,
    noise: float = 0.01,
    background_points: int = 300,
    object_points: int = 8,
    spots: int = 16,
    saturated_spots: int = 8,
    shininess: float | None = None,
    seed: int = 0,
    device: str | None = None,
) -> PhotoSet:
    """Render photographs of a synthetic scene and write them with a COLMAP model.

    Args:
        synthetic: The :class:`~warpspec.synthetic.SyntheticScene` (surface, cameras, light).
        folder: Output folder (created; files already there are replaced).
        scale: Image size relative to the scene's intrinsics (``0.25``: 160x120 from 640x480);
            ``scale * width`` and ``scale * height`` must be whole numbers.
        samples: Samples per pixel along each axis (anti-aliasing).
        noise: Standard deviation of the Gaussian sensor noise (1 is white).
        background_points: How many 3D points of the floor and walls the model holds.
        object_points: How many extra 3D points on the object (besides the scene's own point
            constraints, which are always included when some camera sees them).
        spots: Bright texture spots on the floor and walls (each also a background point).
        saturated_spots: How many of them saturate like a highlight.
        shininess: Blinn-Phong exponent; by default chosen from the surface's curvature at the
            highlights so that a highlight spans about 2 pixels.
        seed: Seed of the texture, the points, the spots and the noise.
        device: Warp device (default: CUDA when present, else the CPU).

    Returns:
        What was written (:class:`PhotoSet`).

    Raises:
        InputError: If an option is out of range or the scene cannot be rendered.
    """
    import trimesh
    import warp as wp
    from skimage import io as skio

    from ._runtime import resolve_device
    from .colmap import ColmapCamera, ColmapImage, write_model
    from .kernels.render import launch_shade, launch_trace, launch_visible

    if not (isinstance(scale, int | float) and math.isfinite(scale) and scale > 0):
        raise InputError(f"scale: expected a positive number, got {scale!r}")
    intr = synthetic.intrinsics
    width, height = intr.width * scale, intr.height * scale
    if abs(width - round(width)) > 1e-9 or abs(height - round(height)) > 1e-9:
        raise InputError(f"scale: {scale:g} x {intr.width}x{intr.height} is not a whole number "
                         "of pixels")
    width, height = int(round(width)), int(round(height))
    for name, value, low in (("samples", samples, 1), ("background_points", background_points, 0),
                             ("object_points", object_points, 0), ("spots", spots, 0),
                             ("saturated_spots", saturated_spots, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise InputError(f"{name}: expected an integer >= {low}, got {value!r}")
    if saturated_spots > spots:
        raise InputError(f"saturated_spots: {saturated_spots} is more than spots={spots}")
    if spots > background_points:
        raise InputError(f"spots: {spots} is more than background_points={background_points}")
    if not (math.isfinite(noise) and noise >= 0):
        raise InputError(f"noise: expected a number >= 0, got {noise!r}")
    dev = resolve_device(device)
    rng = np.random.default_rng(seed)
    out = Path(folder)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "sparse" / "0").mkdir(parents=True, exist_ok=True)

    # Cameras in COLMAP's pixels at the new size: K scaled, principal point + half a pixel.
    K0 = intr.matrix()
    K = np.diag([scale, scale, 1.0]) @ (K0 + np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]))
    poses, matrices, centres = [], [], []
    for k, P in enumerate(synthetic.cameras):
        Rt = np.linalg.solve(K0, P)
        R, t = Rt[:, :3], Rt[:, 3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-8) or np.linalg.det(R) < 0:
            raise SceneError(f"cameras[{k}]: not K [R | t] with the scene's intrinsics")
        poses.append((R, t))
        matrices.append(K @ Rt)
        centres.append(-R.T @ t)
    centres = np.array(centres)

    # The object and the room.
    obj = synthetic.truth_mesh()
    surface = synthetic.surface
    overts = np.asarray(obj.vertices, dtype=np.float64)
    ofaces = np.asarray(obj.faces, dtype=np.int64)
    onormals = surface.normal(overts)
    everything = np.concatenate([overts, centres])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    extent = float((hi - lo).max())
    lo, hi = lo - 0.4 * extent, hi + 0.4 * extent
    rverts, rfaces, rnormals = _room(lo, hi)
    verts = np.concatenate([overts, rverts])
    faces = np.concatenate([ofaces, rfaces + len(overts)])
    vnormals = np.concatenate([onormals, rnormals])
    mesh = wp.Mesh(points=wp.array(verts, dtype=wp.vec3, device=dev),
                   indices=wp.array(faces.ravel(), dtype=int, device=dev))
    wnormals = wp.array(vnormals, dtype=wp.vec3, device=dev)
    obj_centre = overts.mean(axis=0)
    slack = 1e-4 * extent

    # Points: on the object (the scene's constraints and a few more) and on the room.
    extra = (np.asarray(trimesh.sample.sample_surface(obj, object_points, seed=seed)[0])
             if object_points else np.zeros((0, 3)))
    if len(extra):
        extra = surface.closest_point(extra)
    opts = np.concatenate([synthetic.points, extra]).reshape(-1, 3)
    bcand = _sample_room(lo, hi, 20 * max(background_points, 1), rng)

    def observations(pts: np.ndarray) -> np.ndarray:
        """Which camera sees each point, in the frame, ``(cameras, points)`` booleans."""
        seen = launch_visible(mesh, wp.array(centres, dtype=wp.vec3, device=dev),
                              wp.array(pts, dtype=wp.vec3, device=dev), slack=slack).numpy()
        seen = seen.astype(bool)
        for c, P in enumerate(matrices):
            h = pts @ P[:, :3].T + P[:, 3]
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = h[:, :2] / h[:, 2:3]
            inside = ((h[:, 2] > 0) & (uv[:, 0] >= 1) & (uv[:, 0] <= width - 1)
                      & (uv[:, 1] >= 1) & (uv[:, 1] <= height - 1))
            seen[c] &= inside
        return seen

    oseen = observations(opts)
    # A feature under a saturated highlight cannot be matched: no observation within 3 px.
    pix = scale * (synthetic.clean_pixels + 0.5)
    cams = synthetic.camera_indices
    for c, q in zip(cams, pix, strict=True):
        h = opts @ matrices[c][:, :3].T + matrices[c][:, 3]
        near = np.linalg.norm(h[:, :2] / h[:, 2:3] - q, axis=1) < 3.0
        oseen[c] &= ~near
    keep = oseen.sum(axis=0) >= 2
    opts, oseen = opts[keep], oseen[:, keep]
    bseen = observations(bcand)
    views = bseen.sum(axis=0)
    good = np.flatnonzero(views >= 2)
    if len(good) < background_points:
        raise InputError(f"background_points: only {len(good)} room points are seen by two "
                         "cameras")
    good = good[rng.permutation(len(good))[:background_points]]
    # The spots: the background points seen by the most cameras.
    order = good[np.argsort(-views[good], kind="stable")]
    good = np.concatenate([order[:spots], np.setdiff1d(good, order[:spots])])
    bpts, bseen = bcand[good], bseen[:, good]
    f_px = K[0, 0]
    dist = np.median(np.linalg.norm(centres[:, None] - bpts[None, :spots], axis=2), axis=0) \
        if spots else np.zeros(0)
    spot_xyz = bpts[:spots]
    spot_r = 1.5 * dist / f_px  # 1.5 pixels of radius, seen from a typical camera
    spot_v = np.where(np.arange(spots) < saturated_spots, 1.6, 0.62)

    # Shininess from the curvature at the highlights: a lobe of about 1 px (sigma).
    light = synthetic.scene_dict["light"]
    kind = light["type"]
    if shininess is None:
        values = []
        for x, c in zip(synthetic.truth_points, centres[synthetic.camera_indices],
                        strict=True):
            rho = _curvature_radius(surface, x, extent)
            d = float(np.linalg.norm(c - x))
            values.append((f_px * rho / d) ** 2)
        shininess = float(np.clip(np.median(values), 50.0, 2.0e5)) if values else 2000.0
    if kind == "directional":
        light_vec, light_ref = np.asarray(light["direction"], dtype=np.float64), 1.0
    elif kind == "point":
        light_vec = np.asarray(light["position"], dtype=np.float64)
        light_ref = float(np.linalg.norm(light_vec - obj_centre))
    else:
        light_vec = np.zeros(3)
        light_ref = float(np.median(np.linalg.norm(centres - obj_centre, axis=1)))

    wspots = wp.array(spot_xyz.reshape(-1, 3), dtype=wp.vec3, device=dev)
    wradius = wp.array(spot_r.astype(np.float32), dtype=float, device=dev)
    wvalue = wp.array(spot_v.astype(np.float32), dtype=float, device=dev)
    names = tuple(f"view_{k:03d}.png" for k in range(len(matrices)))
    ss = samples
    for k, (P, c) in enumerate(zip(matrices, centres, strict=True)):
        M = P[:, :3]
        m_inv = np.linalg.inv(M) * np.sign(np.linalg.det(M))
        t, face, normal, direction = launch_trace(mesh, wnormals, c, m_inv, width=width,
                                                  height=height, ss=ss, max_t=10 * extent)
        # Exact normals of the analytic surface where the object is hit.
        fa = face.numpy()
        on_object = (fa >= 0) & (fa < len(ofaces))
        if on_object.any():
            nrm = normal.numpy()
            p = c + t.numpy()[on_object][:, None] * direction.numpy()[on_object]
            nrm[on_object] = surface.normal(p)
            normal = wp.array(nrm, dtype=wp.vec3, device=dev)
        rgb = launch_shade(mesh, c, direction, t, face, normal, object_faces=len(ofaces),
                           light_type=LIGHT_CODES[kind], light_vec=light_vec,
                           light_ref=light_ref, shininess=shininess, specular=4.0,
                           object_albedo=(0.22, 0.2, 0.25), ambient=0.25,
                           texture_scale=extent / 40.0, seed=seed, spots=wspots,
                           spot_radius=wradius, spot_value=wvalue, eps=slack).numpy()
        img = rgb.reshape(height, ss, width, ss, 3).mean(axis=(1, 3))
        img = img + noise * rng.standard_normal(img.shape)
        img8 = np.clip(np.rint(255 * img), 0, 255).astype(np.uint8)
        skio.imsave(out / "images" / names[k], img8, check_contrast=False)

    # The COLMAP model.
    camera = ColmapCamera(1, "PINHOLE", width, height, (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    all_pts = np.concatenate([opts, bpts])
    all_seen = np.concatenate([oseen, bseen], axis=1)
    point_ids = np.arange(1, len(all_pts) + 1)
    images, obs = [], []
    tracks: list[list[tuple[int, int]]] = [[] for _ in all_pts]
    for k, (P, (R, t)) in enumerate(zip(matrices, poses, strict=True)):
        idx = np.flatnonzero(all_seen[k])
        h = all_pts[idx] @ P[:, :3].T + P[:, 3]
        uv = h[:, :2] / h[:, 2:3]
        rows = np.column_stack([uv, point_ids[idx]])
        for j, i in enumerate(idx):
            tracks[i].append((k + 1, j))
        images.append(ColmapImage(k + 1, tuple(_quaternion(R)), tuple(t), 1, names[k]))
        obs.append(rows)
    errors = np.zeros(len(all_pts))
    colours = np.full((len(all_pts), 3), 128, dtype=np.int64)
    write_model(out / "sparse" / "0", {1: camera}, images, obs, point_ids, all_pts, colours,
                errors, tracks, binary=True, text=True)

    # The truth.
    with open(out / "highlights_true.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["image", "u", "v"])
        for c, (u, v) in zip(cams, pix, strict=True):
            w.writerow([names[c], repr(float(u)), repr(float(v))])
    obj.export(out / "truth.ply")
    synthetic.to_json(out / "scene_true.json")
    n_obj = len(opts)
    return PhotoSet(
        folder=out, image_names=names, width=width, height=height,
        highlights=np.column_stack([cams, pix]),
        object_point_ids=tuple(int(i) for i in point_ids[:n_obj]),
        background_point_ids=tuple(int(i) for i in point_ids[n_obj:]),
        spot_point_ids=tuple(int(i) for i in point_ids[n_obj:n_obj + spots]),
        saturated_spot_ids=tuple(int(i) for i in point_ids[n_obj:n_obj + saturated_spots]),
        room=(lo, hi),
    )


# --------------------------------------------------------------------------------------------
# Structure from motion (optional: pycolmap)


def run_sfm(images: str | os.PathLike, workspace: str | os.PathLike) -> Path:
    """Run COLMAP's structure from motion on photographs with pycolmap (optional extra).

    SIFT features, exhaustive matching and incremental mapping, with COLMAP's defaults; the
    models go to ``workspace/sparse/N`` (binary), the largest first, as ``colmap mapper``
    writes them.

    Args:
        images: The folder of photographs.
        workspace: A new or empty folder for ``database.db`` and ``sparse/``.

    Returns:
        The folder of the first model, ``workspace/sparse/0``.

    Raises:
        InputError: If pycolmap is not installed, the workspace is in use, or no image could
            be registered.
    """
    try:
        import pycolmap
    except ImportError:
        raise InputError("--sfm: needs pycolmap (pip install 'warpspec[photos]')") from None
    images, workspace = Path(images), Path(workspace)
    if not images.is_dir():
        raise InputError(f"--sfm: {images} is not a folder of photographs")
    if workspace.exists() and any(workspace.iterdir()):
        raise InputError(f"--sfm: {workspace} is not empty; give a new or empty folder")
    workspace.mkdir(parents=True, exist_ok=True)
    database = workspace / "database.db"
    pycolmap.extract_features(database, images)
    pycolmap.match_exhaustive(database)
    maps = pycolmap.incremental_mapping(database, images, workspace / "sparse")
    if not maps:
        raise InputError(f"--sfm: COLMAP registered none of the photographs of {images}")
    return workspace / "sparse" / "0"
