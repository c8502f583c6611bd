"""Cameras that see chosen highlights: intrinsics, placement, patches and highlight search."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.optimize import root

from ..errors import SceneError
from ..geometry import (
    CameraLight,
    DirectionalLight,
    LightModel,
    _dot,
    _normalize,
    _points,
    _unit3,
    _vec3,
    as_light,
    reflect,
)
from .surfaces import MeshSurface, Surface, _tangent_basis

# --------------------------------------------------------------------------------------------
# Cameras
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics.

    Attributes:
        focal: Focal length in pixels.
        width: Image width in pixels.
        height: Image height in pixels.
        principal: Principal point ``(u, v)``; the image centre by default.
    """

    focal: float = 800.0
    width: int = 640
    height: int = 480
    principal: tuple[float, float] | None = None

    @property
    def centre(self) -> np.ndarray:
        """The principal point ``(2,)``."""
        if self.principal is not None:
            return np.asarray(self.principal, dtype=np.float64)
        return np.array([(self.width - 1) / 2, (self.height - 1) / 2])

    def matrix(self) -> np.ndarray:
        """The calibration matrix ``K`` (3x3)."""
        cu, cv = self.centre
        return np.array([[self.focal, 0.0, cu], [0.0, self.focal, cv], [0.0, 0.0, 1.0]])

    def contains(self, pixels: np.ndarray, *, margin: float = 0.0) -> np.ndarray:
        """Whether pixels ``(N, 2)`` lie in the image, ``margin`` pixels from its border."""
        p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        return ((p[:, 0] >= margin) & (p[:, 0] <= self.width - 1 - margin)
                & (p[:, 1] >= margin) & (p[:, 1] <= self.height - 1 - margin))

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"focal": self.focal, "width": self.width, "height": self.height,
                "principal": self.centre.tolist()}




def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the unit vector ``a`` to the unit vector ``b``."""
    k = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:
        raise SceneError("camera: cannot turn a pixel ray into its opposite")
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + kx + kx @ kx / (1 + c)


def look_at(
    centre: Sequence[float],
    target: Sequence[float],
    *,
    intrinsics: Intrinsics | None = None,
    pixel: Sequence[float] | None = None,
    up: Sequence[float] = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """A camera at ``centre`` whose ray through ``pixel`` passes through ``target``.

    Args:
        centre: Camera centre ``(3,)``.
        target: World point to image at ``pixel`` ``(3,)``.
        intrinsics: Intrinsics (default :class:`Intrinsics`).
        pixel: Pixel where ``target`` appears; the principal point by default.
        up: World direction that appears up in the image (approximately, when ``pixel`` is off
            centre).

    Returns:
        The camera matrix ``P = K [R | t]`` (3x4), with ``det(R) = 1``.

    Raises:
        SceneError: If ``target`` coincides with ``centre``.
    """
    intrinsics = intrinsics or Intrinsics()
    c = _vec3(centre, "centre")
    w = _vec3(target, "target") - c
    if np.linalg.norm(w) == 0:
        raise SceneError("camera: target coincides with the centre")
    w /= np.linalg.norm(w)
    upv = _unit3(up, "up")
    if abs(np.dot(upv, w)) > 1 - 1e-6:
        upv = np.eye(3)[int(np.argmin(np.abs(w)))]
    right = np.cross(w, upv)
    right /= np.linalg.norm(right)
    down = np.cross(w, right)
    R = np.stack([right, down, w])  # rows: camera x (right), y (down), z (forward)
    K = intrinsics.matrix()
    if pixel is not None:
        a = np.linalg.solve(K, np.array([pixel[0], pixel[1], 1.0]))
        a /= np.linalg.norm(a)
        # Rotate the camera so that the ray of ``pixel`` (a, in camera axes) points along w.
        R = _rotation_between(a, np.array([0.0, 0.0, 1.0])).T @ R
    return K @ np.column_stack([R, -R @ c])



def place_camera(
    point: Sequence[float],
    normal: Sequence[float],
    light: LightModel | dict,
    *,
    distance: float,
    intrinsics: Intrinsics | None = None,
    pixel: Sequence[float] | None = None,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    min_cos: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """A camera that sees the highlight of ``light`` at a surface ``point`` at ``pixel``.

    The camera sits on the mirror direction ``v = 2 (n.L) n - L`` at ``distance`` from the
    point (on the normal for a camera flash), turned so that the ray of ``pixel`` passes
    through the point.

    Args:
        point: Surface point ``(3,)``.
        normal: Outward unit normal there ``(3,)``.
        light: The light.
        distance: Distance from the point to the camera centre.
        intrinsics: Intrinsics (default :class:`Intrinsics`).
        pixel: Pixel of the highlight; the principal point by default.
        up: World direction that appears up in the image.
        min_cos: Smallest accepted ``n.L`` (the light must be in front of the surface).

    Returns:
        The camera matrix (3x4) and its centre ``(3,)``.

    Raises:
        SceneError: If the light is behind the surface at the point (``n.L < min_cos``).
    """
    x = _vec3(point, "point")
    n = _unit3(normal, "normal")
    light = as_light(light)
    if isinstance(light, CameraLight):
        v = n
    else:
        L = light.towards(x[None])[0]
        if np.dot(n, L) < min_cos:
            raise SceneError(
                f"point {x.tolist()}: the light is behind or grazing the surface "
                f"(n.L = {np.dot(n, L):.3g} < {min_cos})"
            )
        v = reflect(n, L)
        v /= np.linalg.norm(v)
    c = x + float(distance) * v
    return look_at(c, x, intrinsics=intrinsics, pixel=pixel, up=up), c


# --------------------------------------------------------------------------------------------
# Patches, clipping and point spreading
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Halfspace:
    """The half-space ``(x - point) . normal >= 0``."""

    point: np.ndarray
    normal: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vec3(self.point, "halfspace.point"))
        object.__setattr__(self, "normal", _unit3(self.normal, "halfspace.normal"))

    def distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance ``(N,)`` to the bounding plane, positive inside."""
        return (_points(x) - self.point) @ self.normal

    def contains(self, x: np.ndarray, *, margin: float = 0.0) -> np.ndarray:
        """Whether points ``(N, 3)`` lie inside, at least ``margin`` from the plane."""
        return self.distance(x) >= margin


def _in_patch(patch: Sequence[Halfspace], x: np.ndarray, *, margin: float = 0.0) -> np.ndarray:
    keep = np.ones(len(_points(x)), dtype=bool)
    for hs in patch:
        keep &= hs.contains(x, margin=margin)
    return keep


def _clip_once(vertices: np.ndarray, faces: np.ndarray, hs: Halfspace
               ) -> tuple[np.ndarray, np.ndarray]:
    s = hs.distance(vertices)
    # Vertices within rounding of the plane count as inside (no sliver triangles).
    tol = 1e-12 * max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    inside = s >= -tol
    cnt = inside[faces].sum(axis=1)
    out_faces = [faces[cnt == 3]]
    new_vertices = [vertices]
    n0 = len(vertices)

    def cut(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        t = np.clip(s[i] / (s[i] - s[j]), 0.0, 1.0)
        return vertices[i] + (vertices[j] - vertices[i]) * t[:, None]

    for keep_count in (1, 2):
        f = faces[cnt == keep_count]
        if len(f) == 0:
            continue
        ins = inside[f]
        # Roll each triangle (keeping its winding) so that the pattern is canonical:
        # one inside vertex first, or the one outside vertex last.
        first = np.argmax(ins, axis=1) if keep_count == 1 else (np.argmin(ins, axis=1) + 1) % 3
        r = (first[:, None] + np.arange(3)) % 3
        f = np.take_along_axis(f, r, axis=1)
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        base = n0 + sum(len(v) for v in new_vertices[1:])
        m = len(f)
        if keep_count == 1:
            new_vertices += [cut(a, b), cut(a, c)]
            ab = base + np.arange(m)
            ac = base + m + np.arange(m)
            out_faces.append(np.stack([a, ab, ac], 1))
        else:
            new_vertices += [cut(b, c), cut(a, c)]
            bc = base + np.arange(m)
            ca = base + m + np.arange(m)
            out_faces += [np.stack([a, b, bc], 1), np.stack([a, bc, ca], 1)]
    return np.concatenate(new_vertices), np.concatenate(out_faces)


def clip_mesh(mesh: trimesh.Trimesh, patch: Sequence[Halfspace]) -> trimesh.Trimesh:
    """Clip a mesh to the intersection of half-spaces, cutting triangles along the planes.

    Args:
        mesh: The mesh.
        patch: Half-spaces to keep; an empty sequence returns a copy.

    Returns:
        The clipped mesh (winding kept, duplicate vertices merged, unused ones removed).
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces)
    for hs in patch:
        v, f = _clip_once(v, f, hs)
    out = trimesh.Trimesh(vertices=v, faces=f, process=False)
    out.merge_vertices()
    out.update_faces(out.nondegenerate_faces())
    out.remove_unreferenced_vertices()
    return out


def spread_points(candidates: np.ndarray, count: int, *, start: Sequence[float] | None = None
                  ) -> np.ndarray:
    """Pick ``count`` well-spread points from ``candidates`` by farthest-point sampling.

    Args:
        candidates: Candidate points ``(N, 3)``.
        count: How many to pick.
        start: The first pick is the candidate nearest to this point (default the centroid).

    Returns:
        The chosen points ``(count, 3)``, deterministic.

    Raises:
        SceneError: If there are fewer candidates than ``count``.
    """
    cand = _points(candidates)
    if len(cand) < count:
        raise SceneError(f"spread_points: {count} points asked from {len(cand)} candidates")
    s = cand.mean(axis=0) if start is None else _vec3(start, "start")
    chosen = [int(np.argmin(np.linalg.norm(cand - s, axis=1)))]
    d = np.linalg.norm(cand - cand[chosen[0]], axis=1)
    for _ in range(count - 1):
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(cand - cand[i], axis=1))
    return cand[chosen]


# --------------------------------------------------------------------------------------------
# Highlight search for a camera on a path
# --------------------------------------------------------------------------------------------


def _visible(surface: Surface, centre: np.ndarray, x: np.ndarray, *, rtol: float = 1e-7
             ) -> bool:
    """Whether the first hit of the ray from ``centre`` toward ``x`` is ``x`` itself."""
    d = x - centre
    dist = float(np.linalg.norm(d))
    t = surface.intersect(centre[None], (d / dist)[None], t_min=1e-9 * dist)[0]
    return bool(np.isfinite(t) and abs(t - dist) <= rtol * dist)


def _bisector_error(surface: Surface, x: np.ndarray, centre: np.ndarray, light: LightModel
                    ) -> np.ndarray:
    """Angle (radians) between the normal and the bisector of light and view, per point."""
    x = _points(x)
    n = surface.normal(x)
    e = _normalize(centre - x)
    h = _normalize(light.towards(x, centre) + e)
    ang = np.arctan2(np.linalg.norm(np.cross(n, h), axis=1), _dot(n, h))
    facing = (_dot(n, e) > 0) & (_dot(n, light.towards(x, centre)) > 0)
    return np.where(facing, ang, np.inf)


def _mesh_highlight(surface: MeshSurface, centre: np.ndarray, light: LightModel,
                    patch: Sequence[Halfspace]) -> np.ndarray | None:
    m = surface._mesh
    tri = np.asarray(m.triangles)
    n = surface._face_normals
    a = tri[:, 0]
    c = centre
    side = _dot(c - a, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        if isinstance(light, CameraLight):
            x = c - side[:, None] * n
            ok = side > 0
        elif isinstance(light, DirectionalLight):
            v = reflect(n, light.direction[None])
            s = side / _dot(v, n)
            x = c - s[:, None] * v
            ok = (_dot(n, light.direction[None]) > 0) & (side > 0) & (s > 0)
        else:
            p = light.position
            mirror = p - 2 * _dot(p - a, n)[:, None] * n
            t = _dot(a - c, n) / _dot(mirror - c, n)
            x = c + t[:, None] * (mirror - c)
            ok = (side > 0) & (_dot(p - a, n) > 0) & (t > 0) & (t < 1)
    # Inside the triangle (barycentric coordinates).
    v0, v1 = tri[:, 1] - a, tri[:, 2] - a
    w = x - a
    d00, d01, d11 = _dot(v0, v0), _dot(v0, v1), _dot(v1, v1)
    d20, d21 = _dot(w, v0), _dot(w, v1)
    den = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        bv = (d11 * d20 - d01 * d21) / den
        bw = (d00 * d21 - d01 * d20) / den
    ok &= (bv >= 1e-9) & (bw >= 1e-9) & (bv + bw <= 1 - 1e-9)
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        return None
    idx = idx[np.argsort(np.linalg.norm(x[idx] - c, axis=1))]
    for i in idx:
        if _in_patch(patch, x[i][None])[0] and _visible(surface, c, x[i]):
            return x[i]
    return None


def find_highlight(
    surface: Surface,
    centre: Sequence[float],
    light: LightModel | dict,
    *,
    candidates: np.ndarray | None = None,
    patch: Sequence[Halfspace] = (),
    tries: int = 8,
    tol: float = 1e-11,
) -> np.ndarray | None:
    """The surface point where a camera at ``centre`` sees the highlight of ``light``.

    That is the point whose normal bisects the directions to the light and to the camera. For
    an analytic surface the best candidates (smallest angle between the normal and the
    bisector) are refined by a root finder on a local chart until the angle is below ``tol``;
    for a :class:`MeshSurface` each face is solved exactly. The point must lie in ``patch``, face
    both camera and light, and be visible from the camera.

    Args:
        surface: The surface.
        centre: Camera centre ``(3,)``.
        light: The light.
        candidates: Dense surface points to start from (default: :meth:`Surface.sample`).
        patch: Half-spaces the highlight must lie in.
        tries: How many of the best candidates to refine.
        tol: Largest accepted angle (radians) between the normal and the bisector.

    Returns:
        The highlight point ``(3,)``, or ``None`` when there is no valid one.
    """
    c = _vec3(centre, "centre")
    light = as_light(light)
    if isinstance(surface, MeshSurface):
        return _mesh_highlight(surface, c, light, patch)
    cand = surface.sample(20_000) if candidates is None else _points(candidates)
    err = _bisector_error(surface, cand, c, light)
    order = np.argsort(err)[:tries]
    tried: list[np.ndarray] = []
    for i in order:
        if not np.isfinite(err[i]):
            break
        x0 = surface.closest_point(cand[i][None])[0]
        if any(np.linalg.norm(x0 - t) < 1e-9 * (1 + np.linalg.norm(t)) for t in tried):
            continue
        tried.append(x0)
        x = _refine_highlight(surface, x0, c, light, tol=tol)
        if x is not None and _in_patch(patch, x[None])[0] and _visible(surface, c, x):
            return x
    return None


def _refine_highlight(surface: Surface, x0: np.ndarray, c: np.ndarray, light: LightModel, *,
                      tol: float) -> np.ndarray | None:
    """Solve for the point near ``x0`` whose normal bisects light and view, on a chart."""
    chart = surface.chart(x0)
    t1, t2 = _tangent_basis(surface.normal(x0[None])[0])

    def residual(uv: np.ndarray) -> np.ndarray:
        x = chart(uv)[None]
        n = surface.normal(x)[0]
        h = _normalize(light.towards(x, c) + _normalize(c - x))[0]
        tang = h - np.dot(h, n) * n
        return np.array([np.dot(tang, t1), np.dot(tang, t2)])

    sol = root(residual, np.zeros(2), method="hybr", options={"xtol": 1e-15})
    x = chart(sol.x)
    if not np.all(np.isfinite(x)):
        return None
    if _bisector_error(surface, x[None], c, light)[0] > tol:
        return None
    return x


def find_highlights(
    surface: Surface,
    centre: Sequence[float],
    light: LightModel | dict,
    *,
    candidates: np.ndarray,
    patch: Sequence[Halfspace] = (),
    max_count: int = 4,
    separation: float | None = None,
    seeds: int = 24,
    tol: float = 1e-11,
) -> np.ndarray:
    """Every visible highlight a camera at ``centre`` sees (a non-convex surface has several).

    The candidates whose normal is within 0.5 radian of the bisector of light and view are
    grouped greedily (best first, one seed per ``separation``); each seed is refined as in
    :func:`find_highlight`, and the distinct valid points (in ``patch``, facing camera and
    light, visible) are kept, nearest to the camera first.

    Args:
        surface: An analytic surface (not a :class:`MeshSurface`).
        centre: Camera centre ``(3,)``.
        light: The light.
        candidates: Dense surface points ``(N, 3)`` to start from.
        patch: Half-spaces the highlights must lie in.
        max_count: Most highlights returned.
        separation: Smallest distance between two seeds; default a tenth of the candidates'
            bounding-box diagonal.
        seeds: Most seeds refined.
        tol: Largest accepted angle (radians) between the normal and the bisector.

    Returns:
        The highlight points ``(K, 3)``, ``K <= max_count`` (possibly 0).
    """
    c = _vec3(centre, "centre")
    light = as_light(light)
    cand = _points(candidates)
    if separation is None:
        separation = 0.1 * float(np.linalg.norm(np.ptp(cand, axis=0)))
    err = _bisector_error(surface, cand, c, light)
    order = np.argsort(err)
    order = order[err[order] < 0.5]
    chosen: list[np.ndarray] = []
    for i in order:
        if len(chosen) >= seeds:
            break
        if all(np.linalg.norm(cand[i] - s) >= separation for s in chosen):
            chosen.append(cand[i])
    found: list[np.ndarray] = []
    for s in chosen:
        x = _refine_highlight(surface, surface.closest_point(s[None])[0], c, light, tol=tol)
        if x is None or not _in_patch(patch, x[None])[0] or not _visible(surface, c, x):
            continue
        if any(np.linalg.norm(x - f) < 1e-7 * (1 + np.linalg.norm(f)) for f in found):
            continue
        found.append(x)
    found.sort(key=lambda x: float(np.linalg.norm(x - c)))
    return np.asarray(found[:max_count], dtype=np.float64).reshape(-1, 3)
