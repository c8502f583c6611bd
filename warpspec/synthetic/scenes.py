"""Synthetic scenes: cameras placed on highlights, noise and outliers, the scene file."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from ..errors import SceneError
from ..geometry import (
    CameraLight,
    DirectionalLight,
    LightModel,
    PointLight,
    _dot,
    _normalize,
    _points,
    _vec3,
    as_light,
    pixel_rays,
    project,
)
from .cameras import (
    Halfspace,
    Intrinsics,
    _in_patch,
    _visible,
    clip_mesh,
    find_highlight,
    find_highlights,
    look_at,
    place_camera,
)
from .surfaces import MeshSurface, Surface

if TYPE_CHECKING:
    from ..scene import Scene


# --------------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------------


def corrupt_pixels(
    pixels: np.ndarray,
    *,
    intrinsics: Intrinsics,
    noise: float = 0.0,
    outliers: float = 0.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Add Gaussian pixel noise and replace a fraction of the pixels by random ones.

    The noise is drawn first (``numpy.random.default_rng(seed)``), then
    ``round(outliers * N)`` distinct pixels become outliers, uniform over the image. Noisy
    pixels are clamped to the image.

    Args:
        pixels: Clean pixels ``(N, 2)``.
        intrinsics: The image the pixels belong to.
        noise: Standard deviation of the noise in pixels (>= 0).
        outliers: Fraction of outliers in ``[0, 1]``.
        seed: Random seed.

    Returns:
        The corrupted pixels ``(N, 2)`` and the outlier mask ``(N,)``.

    Raises:
        SceneError: If ``noise`` or ``outliers`` is out of range.
    """
    if not (np.isfinite(noise) and noise >= 0):
        raise SceneError(f"noise: must be a non-negative number of pixels, got {noise!r}")
    if not (np.isfinite(outliers) and 0 <= outliers <= 1):
        raise SceneError(f"outliers: must be a fraction in [0, 1], got {outliers!r}")
    rng = np.random.default_rng(seed)
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2).copy()
    n = len(p)
    p += float(noise) * rng.standard_normal((n, 2))
    hi = np.array([intrinsics.width - 1, intrinsics.height - 1], dtype=np.float64)
    p = np.clip(p, 0.0, hi)
    mask = np.zeros(n, dtype=bool)
    k = int(round(outliers * n))
    if k:
        idx = rng.choice(n, size=k, replace=False)
        p[idx] = rng.uniform(0.0, 1.0, size=(k, 2)) * hi
        mask[idx] = True
    return p, mask


def jitter_points(synthetic: SyntheticScene, *, sigma: float, seed: int = 0) -> SyntheticScene:
    """The scene with Gaussian noise added to each coordinate of its point constraints.

    Structure from motion's points are never exact; this is its noise. The draw has its own
    stream (``numpy.random.default_rng((seed, POINT_NOISE_STREAM))``), so the pixels' noise
    and outliers of the same seed stay as they were. A point the noise carries out of the
    domain is clamped onto the domain's face. Nothing of ``synthetic`` is modified.

    Args:
        synthetic: The scene.
        sigma: Standard deviation of the noise per coordinate, in the scene's units (>= 0).
        seed: Random seed.

    Returns:
        A new scene whose points moved; its ``clean_points`` keeps the points before.

    Raises:
        SceneError: If ``sigma`` is negative or not finite.
    """
    if not (np.isfinite(sigma) and sigma >= 0):
        raise SceneError(f"sigma: must be a non-negative length, got {sigma!r}")
    clean = synthetic.points if synthetic.clean_points is None else synthetic.clean_points
    rng = np.random.default_rng((int(seed), POINT_NOISE_STREAM))
    lo, hi = synthetic.domain
    moved = np.clip(synthetic.points + float(sigma) * rng.standard_normal(synthetic.points.shape),
                    lo, hi)
    scene_dict = copy.deepcopy(synthetic.scene_dict)
    scene_dict["points"] = moved.tolist()
    return replace(synthetic, scene_dict=scene_dict, clean_points=np.array(clean, copy=True))


POINT_NOISE_STREAM = 0x5EED
"""Second entry of the point noise's seed, which keeps its draw apart from the pixels'."""


def _domain_dict(domain: Any) -> dict:
    if isinstance(domain, dict):
        lo, hi = domain.get("min"), domain.get("max")
    else:
        lo, hi = domain
    lo, hi = _vec3(lo, "domain.min"), _vec3(hi, "domain.max")
    if np.any(hi <= lo):
        raise SceneError(f"domain: max must exceed min, got min={lo.tolist()} max={hi.tolist()}")
    return {"min": lo.tolist(), "max": hi.tolist()}


def _inside_box(dom: dict, x: np.ndarray) -> np.ndarray:
    lo, hi = np.asarray(dom["min"]), np.asarray(dom["max"])
    x = _points(x)
    return np.all((x >= lo) & (x <= hi), axis=1)


@dataclass(eq=False)
class SyntheticScene:
    """A scene in the version-1 format together with its ground truth.

    Attributes:
        name: Scene name.
        scene_dict: The scene, JSON-ready (docs/DESIGN.md section 10).
        surface: The true surface.
        truth_points: True specular points ``(M, 3)``, one per specularity, in file order.
        truth_normals: True outward unit normals at ``truth_points`` ``(M, 3)``.
        light_directions: Unit vectors toward the light at ``truth_points`` ``(M, 3)``.
        clean_pixels: Noise-free pixels of the specularities ``(M, 2)``.
        outlier_mask: Which specularities were replaced by random pixels ``(M,)``.
        camera_centres: Camera centres ``(K, 3)``.
        intrinsics: Intrinsics shared by the cameras.
        patch: Half-spaces that cut the truth mesh out of the surface.
        mesh_options: Options passed to ``surface.mesh`` for the truth mesh.
        closed: Whether the truth mesh is closed (watertight) rather than an open surface.
        euler: Euler number (V - E + F) of the truth mesh: 2 for a sphere, 0 for a torus or
            an open tube, 1 for a patch (a disc); ``None`` when not stated.
        false_highlights: How outliers were drawn: ``"image"`` (a pixel anywhere in the
            image) or ``"surface"`` (a pixel whose ray meets the truth where the normal of
            the reflection law is wrong by 15 degrees or more).
        clean_points: The point constraints before :func:`jitter_points` moved them
            ``(S, 3)``; ``None`` when they carry no noise.
    """

    name: str
    scene_dict: dict
    surface: Surface
    truth_points: np.ndarray
    truth_normals: np.ndarray
    light_directions: np.ndarray
    clean_pixels: np.ndarray
    outlier_mask: np.ndarray
    camera_centres: np.ndarray
    intrinsics: Intrinsics
    patch: tuple[Halfspace, ...] = ()
    mesh_options: dict = field(default_factory=dict)
    closed: bool = False
    euler: int | None = None
    false_highlights: str = "image"
    clean_points: np.ndarray | None = None

    @property
    def cameras(self) -> list[np.ndarray]:
        """Camera matrices (3x4 arrays)."""
        return [np.asarray(c["P"], dtype=np.float64) for c in self.scene_dict["cameras"]]

    @property
    def pixels(self) -> np.ndarray:
        """Pixels of the specularities as written in the scene ``(M, 2)``."""
        return np.array([s["pixel"] for s in self.scene_dict["specularities"]], dtype=np.float64)

    @property
    def camera_indices(self) -> np.ndarray:
        """Camera index of each specularity ``(M,)``."""
        return np.array([s["camera"] for s in self.scene_dict["specularities"]], dtype=np.int64)

    @property
    def points(self) -> np.ndarray:
        """Point constraints ``(S, 3)``."""
        return np.asarray(self.scene_dict["points"], dtype=np.float64).reshape(-1, 3)

    @property
    def domain(self) -> tuple[np.ndarray, np.ndarray]:
        """The domain box ``(min, max)``."""
        d = self.scene_dict["domain"]
        return np.asarray(d["min"], dtype=np.float64), np.asarray(d["max"], dtype=np.float64)

    @property
    def inliers(self) -> np.ndarray:
        """Mask of the specularities that are not outliers ``(M,)``."""
        return ~self.outlier_mask

    def truth_mesh(self, **options: Any) -> trimesh.Trimesh:
        """The truth mesh: ``surface.mesh`` clipped to ``patch`` (options override defaults)."""
        return clip_mesh(self.surface.mesh(**{**self.mesh_options, **options}), self.patch)

    def scene(self) -> Scene:
        """The scene as a :class:`warpspec.scene.Scene`."""
        from ..scene import Scene

        return Scene.from_dict(copy.deepcopy(self.scene_dict))

    def truth_dict(self) -> dict:
        """The ground truth, JSON-ready."""
        return {
            "name": self.name,
            "truth_points": self.truth_points.tolist(),
            "truth_normals": self.truth_normals.tolist(),
            "light_directions": self.light_directions.tolist(),
            "points": self.points.tolist(),
            "clean_points": (self.points if self.clean_points is None
                             else self.clean_points).tolist(),
            "clean_pixels": self.clean_pixels.tolist(),
            "outliers": np.flatnonzero(self.outlier_mask).tolist(),
            "camera_centres": self.camera_centres.tolist(),
            "intrinsics": self.intrinsics.to_dict(),
            "closed": bool(self.closed),
            "euler": self.euler,
            "false_highlights": self.false_highlights,
        }

    def to_json(self, path: str | Path | None = None) -> str:
        """The scene file text (one camera, specularity or point per line); written if ``path``.

        Args:
            path: Where to write the file, or ``None`` to only return the text.
        """
        d = self.scene_dict
        lines = ["{"]
        items = list(d.items())
        for k, (key, value) in enumerate(items):
            comma = "," if k < len(items) - 1 else ""
            if isinstance(value, list) and value:
                lines.append(f"  {json.dumps(key)}: [")
                for j, item in enumerate(value):
                    sep = "," if j < len(value) - 1 else ""
                    lines.append(f"    {json.dumps(item)}{sep}")
                lines.append(f"  ]{comma}")
            else:
                lines.append(f"  {json.dumps(key)}: {json.dumps(value)}{comma}")
        lines.append("}")
        text = "\n".join(lines) + "\n"
        if path is not None:
            Path(path).write_text(text)
        return text


def _false_pixels(
    pixels: np.ndarray,
    mask: np.ndarray,
    *,
    surface: Surface,
    cameras: Sequence[np.ndarray],
    centres: np.ndarray,
    camera_of: np.ndarray,
    lights: Sequence[LightModel],
    intrinsics: Intrinsics,
    domain: dict,
    patch: Sequence[Halfspace],
    seed: int,
    min_angle: float = 15.0,
    tries: int = 256,
) -> np.ndarray:
    """Move each outlier onto a pixel whose ray meets the truth where the law's normal is wrong.

    For every masked specularity, pixels of its camera are drawn uniformly (seeded) until one's
    ray first meets the surface inside the domain and the patch at a point where the normal
    the reflection law gives differs from the true one by at least ``min_angle`` degrees: a
    false highlight on the object, as a glint of another light or a texture would give. If no
    draw qualifies the uniform pixel is kept.
    """
    out = pixels.copy()
    rng = np.random.default_rng([int(seed), 104729])
    size = np.array([intrinsics.width - 1, intrinsics.height - 1], dtype=np.float64)
    cos_min = math.cos(math.radians(min_angle))
    for i in np.flatnonzero(mask):
        k = int(camera_of[i])
        trial = rng.uniform(0.0, 1.0, size=(tries, 2)) * size
        c, r = pixel_rays(cameras[k], trial)
        t = surface.intersect(np.tile(c, (tries, 1)), r)
        hit = np.isfinite(t)
        x = c + np.where(hit, t, 0.0)[:, None] * r
        ok = hit & _inside_box(domain, x) & _in_patch(patch, x)
        if not np.any(ok):
            continue
        N = _normalize(lights[k].towards(x, c) - r)
        ok &= _dot(N, surface.normal(x)) < cos_min
        if np.any(ok):
            out[i] = trial[int(np.argmax(ok))]
    return out


def _assemble(
    *,
    name: str,
    surface: Surface,
    light: LightModel | Sequence[LightModel],
    cameras: list[np.ndarray],
    centres: list[np.ndarray],
    truth: np.ndarray,
    pixels: np.ndarray,
    points: np.ndarray,
    domain: Any,
    intrinsics: Intrinsics,
    patch: Sequence[Halfspace],
    mesh_options: dict | None,
    noise: float,
    outliers: float,
    seed: int,
    camera_of: np.ndarray | None = None,
    false_highlights: str = "image",
    closed: bool = False,
    euler: int | None = None,
) -> SyntheticScene:
    dom = _domain_dict(domain)
    centres_arr = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    if np.any(_inside_box(dom, centres_arr)):
        i = int(np.flatnonzero(_inside_box(dom, centres_arr))[0])
        raise SceneError(f"domain: camera {i} at {centres_arr[i].tolist()} lies inside it")
    pts = _points(points)
    for label, arr in (("point constraint", pts), ("specular point", truth)):
        out = ~_inside_box(dom, arr)
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            raise SceneError(f"domain: {label} {i} at {arr[i].tolist()} lies outside it")
    per_camera = not isinstance(light, DirectionalLight | PointLight | CameraLight)
    lights = list(light) if per_camera else [light] * len(cameras)
    if len(lights) != len(cameras):
        raise SceneError(f"light: {len(lights)} lights given for {len(cameras)} cameras")
    cam_of = (np.arange(len(truth)) if camera_of is None
              else np.asarray(camera_of, dtype=np.int64).reshape(-1))
    noisy, mask = corrupt_pixels(pixels, intrinsics=intrinsics, noise=noise,
                                 outliers=outliers, seed=seed)
    if false_highlights == "surface" and np.any(mask):
        noisy = _false_pixels(noisy, mask, surface=surface, cameras=cameras,
                              centres=centres_arr, camera_of=cam_of, lights=lights,
                              intrinsics=intrinsics, domain=dom, patch=patch, seed=seed)
    elif false_highlights not in ("image", "surface"):
        raise SceneError(f"false_highlights: expected 'image' or 'surface', got "
                         f"{false_highlights!r}")
    normals = surface.normal(truth)
    light_dirs = np.stack([lights[k].towards(truth[i][None], centres_arr[k])[0]
                           for i, k in enumerate(cam_of)]) if len(truth) else np.zeros((0, 3))
    cam_dicts = []
    for P, li in zip(cameras, lights, strict=True):
        entry: dict = {"P": np.asarray(P, dtype=np.float64).tolist()}
        if per_camera:
            entry["light"] = li.to_dict()
        cam_dicts.append(entry)
    scene_dict: dict = {"format": "warpspec-scene", "version": 1, "cameras": cam_dicts}
    if not per_camera:
        scene_dict["light"] = light.to_dict()
    scene_dict.update({
        "specularities": [{"camera": int(k), "pixel": [float(p[0]), float(p[1])]}
                          for k, p in zip(cam_of, noisy, strict=True)],
        "points": pts.tolist(),
        "domain": dom,
    })
    return SyntheticScene(
        name=name,
        scene_dict=scene_dict,
        surface=surface,
        truth_points=truth,
        truth_normals=normals,
        light_directions=light_dirs,
        clean_pixels=np.asarray(pixels, dtype=np.float64).reshape(-1, 2),
        outlier_mask=mask,
        camera_centres=centres_arr,
        intrinsics=intrinsics,
        patch=tuple(patch),
        mesh_options=dict(mesh_options or {}),
        closed=closed,
        euler=euler,
        false_highlights=false_highlights,
    )


def scene_from_points(
    surface: Surface,
    specular_points: np.ndarray,
    *,
    light: LightModel | dict,
    points: np.ndarray,
    domain: Any,
    distance: float = 3.0,
    intrinsics: Intrinsics | None = None,
    pixel: str = "random",
    pixel_margin: float = 0.15,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    patch: Sequence[Halfspace] = (),
    name: str = "synthetic",
    mesh_options: dict | None = None,
    noise: float = 0.0,
    outliers: float = 0.0,
    seed: int = 0,
    layout_seed: int = 0,
    false_highlights: str = "image",
    closed: bool = False,
    euler: int | None = None,
) -> SyntheticScene:
    """A scene with one camera per chosen specular point, each seeing its highlight there.

    Args:
        surface: The true surface.
        specular_points: Where the highlights are ``(M, 3)`` (projected onto the surface).
        light: The light (object or scene-file dict).
        points: Point constraints ``(S, 3)``.
        domain: Domain box, ``(min, max)`` or ``{"min": ..., "max": ...}``; the cameras must
            lie outside it and all points inside.
        distance: Distance from each specular point to its camera.
        intrinsics: Intrinsics (default :class:`Intrinsics`).
        pixel: ``"centre"`` (the principal point) or ``"random"`` (uniform in the image, at
            least ``pixel_margin`` of its size from the border, drawn from ``layout_seed``).
        pixel_margin: Border fraction kept free of highlights with ``pixel="random"``.
        up: World direction that appears up in the images.
        patch: Half-spaces cutting the truth mesh out of the surface.
        name: Scene name.
        mesh_options: Options of ``surface.mesh`` for the truth mesh.
        noise: Pixel noise standard deviation (pixels).
        outliers: Fraction of specularities replaced by random pixels.
        seed: Seed of the noise and the outliers.
        layout_seed: Seed of the highlight pixels (the geometry).
        false_highlights: How outliers are drawn (see :func:`scene_from_path`).
        closed: Whether the truth mesh is closed.
        euler: Euler number of the truth mesh.

    Returns:
        The scene with its ground truth.

    Raises:
        SceneError: If a highlight is impossible (light behind the surface), outside the image,
            hidden by the surface, or the domain does not fit.
    """
    intrinsics = intrinsics or Intrinsics()
    light = as_light(light)
    if pixel not in ("centre", "random"):
        raise SceneError(f"pixel: expected 'centre' or 'random', got {pixel!r}")
    truth = surface.closest_point(_points(specular_points))
    normals = surface.normal(truth)
    rng = np.random.default_rng(layout_seed)
    size = np.array([intrinsics.width - 1, intrinsics.height - 1], dtype=np.float64)
    cams, centres, pix = [], [], []
    for i, (x, n) in enumerate(zip(truth, normals, strict=True)):
        target = None
        if pixel == "random":
            target = (pixel_margin + (1 - 2 * pixel_margin) * rng.uniform(size=2)) * size
        P, c = place_camera(x, n, light, distance=distance, intrinsics=intrinsics,
                            pixel=target, up=up)
        q, depth = project(P, x[None])
        if not (depth[0] > 0 and intrinsics.contains(q)[0]):
            raise SceneError(f"specular point {i}: its highlight falls outside the image")
        if surface.implicit(c[None])[0] <= 0:
            raise SceneError(f"specular point {i}: the camera at {c.tolist()} is inside")
        if not _visible(surface, c, x):
            raise SceneError(f"specular point {i} at {x.tolist()}: hidden by the surface")
        cams.append(P)
        centres.append(c)
        pix.append(q[0])
    return _assemble(name=name, surface=surface, light=light, cameras=cams, centres=centres,
                     truth=truth, pixels=np.asarray(pix).reshape(-1, 2), points=points,
                     domain=domain, intrinsics=intrinsics, patch=patch,
                     mesh_options=mesh_options, noise=noise, outliers=outliers, seed=seed,
                     false_highlights=false_highlights, closed=closed, euler=euler)


def scene_from_path(
    surface: Surface,
    centres: np.ndarray,
    *,
    light: LightModel | dict | Sequence[LightModel | dict],
    look_at_points: np.ndarray,
    points: np.ndarray,
    domain: Any,
    candidates: np.ndarray | None = None,
    intrinsics: Intrinsics | None = None,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    patch: Sequence[Halfspace] = (),
    name: str = "path",
    mesh_options: dict | None = None,
    noise: float = 0.0,
    outliers: float = 0.0,
    seed: int = 0,
    per_view: int = 1,
    false_highlights: str = "image",
    closed: bool = False,
    euler: int | None = None,
    max_view_deg: float | None = None,
) -> SyntheticScene:
    """A scene from cameras along a path, like a video: each sees the highlight where it falls.

    For each camera centre the highlight is searched on the surface (:func:`find_highlight`,
    or :func:`find_highlights` when ``per_view > 1``); views without a valid highlight (none in
    the patch, hidden, outside the image) are skipped.

    Args:
        surface: The true surface.
        centres: Camera centres along the path ``(K, 3)``.
        light: The light, or a list of one light per camera (written as each camera's own
            ``light``).
        look_at_points: What each camera looks at (image centre): ``(3,)`` or ``(K, 3)``.
        points: Point constraints ``(S, 3)``.
        domain: Domain box (see :func:`scene_from_points`).
        candidates: Dense surface points to start the highlight search from; default the
            vertices of the truth mesh.
        intrinsics: Intrinsics (default :class:`Intrinsics`).
        up: World direction that appears up in the images.
        patch: Half-spaces the highlights must lie in (and that cut the truth mesh).
        name: Scene name.
        mesh_options: Options of ``surface.mesh`` for the truth mesh.
        noise: Pixel noise standard deviation (pixels).
        outliers: Fraction of specularities replaced by false ones.
        seed: Seed of the noise and the outliers.
        per_view: Most highlights kept per view (a non-convex surface shows several).
        false_highlights: ``"image"``: outliers anywhere in the image; ``"surface"``: on the
            object, with a wrong normal (see :class:`SyntheticScene`).
        closed: Whether the truth mesh is closed.
        euler: Euler number of the truth mesh.
        max_view_deg: Skip highlights seen more obliquely than this (degrees between the
            surface normal and the way back to the camera); ``None``: keep all.

    Returns:
        The scene with its ground truth (the kept views; their specularities in view order).

    Raises:
        SceneError: If no view has a valid highlight, or the domain does not fit.
    """
    intrinsics = intrinsics or Intrinsics()
    centres = _points(centres)
    if isinstance(light, dict | DirectionalLight | PointLight | CameraLight):
        lights = [as_light(light)] * len(centres)
        shared: LightModel | None = lights[0] if len(lights) else as_light(light)
    else:
        lights = [as_light(li) for li in light]
        shared = None
        if len(lights) != len(centres):
            raise SceneError(f"light: {len(lights)} lights given for {len(centres)} cameras")
    targets = np.broadcast_to(np.asarray(look_at_points, dtype=np.float64), centres.shape)
    if candidates is None and not isinstance(surface, MeshSurface):
        candidates = clip_mesh(surface.mesh(**(mesh_options or {})), patch).vertices
    cams, kept, kept_lights, truth, pix, cam_of = [], [], [], [], [], []
    for c, target, li in zip(centres, targets, lights, strict=True):
        if per_view > 1 and not isinstance(surface, MeshSurface):
            found = find_highlights(surface, c, li, candidates=candidates, patch=patch,
                                    max_count=per_view)
        else:
            x = find_highlight(surface, c, li, candidates=candidates, patch=patch)
            found = np.zeros((0, 3)) if x is None else x[None]
        if len(found) and max_view_deg is not None:
            back = c - found
            cos = np.einsum("ij,ij->i", surface.normal(found), back) / np.linalg.norm(back, axis=1)
            found = found[cos >= math.cos(math.radians(max_view_deg))]
        if len(found) == 0:
            continue
        P = look_at(c, target, intrinsics=intrinsics, up=up)
        q, depth = project(P, found)
        ok = (depth > 0) & intrinsics.contains(q)
        if not np.any(ok):
            continue
        for x, qq in zip(found[ok], q[ok], strict=True):
            truth.append(x)
            pix.append(qq)
            cam_of.append(len(cams))
        cams.append(P)
        kept.append(c)
        kept_lights.append(li)
    if not cams:
        raise SceneError("path: no view sees a valid highlight")
    return _assemble(name=name, surface=surface,
                     light=shared if shared is not None else kept_lights, cameras=cams,
                     centres=kept, truth=np.asarray(truth), pixels=np.asarray(pix),
                     points=points, domain=domain, intrinsics=intrinsics, patch=patch,
                     mesh_options=mesh_options, noise=noise, outliers=outliers, seed=seed,
                     camera_of=np.asarray(cam_of), false_highlights=false_highlights,
                     closed=closed, euler=euler)
