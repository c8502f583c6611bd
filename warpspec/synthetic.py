"""Synthetic scenes with ground truth: surfaces, cameras that see chosen highlights, noise.

A synthetic scene is a known surface, a light, and cameras placed so that each sees a specular
highlight at a known surface point: the camera sits on the direction into which the surface
mirrors the light. The scene is written in the version-1 scene format (docs/DESIGN.md section
10) and kept together with its ground truth (specular points, normals, a truth mesh).

Geometry follows docs/DESIGN.md section 2: ``P = K [R | t]``, centre ``c = -M^-1 p4``, the ray
of pixel ``q`` has direction ``normalize(sign(det M) M^-1 q)`` from the camera into the scene, and
the reflection law is ``N = normalize(L - r)`` with ``L`` the unit vector toward the light. Cameras
follow the usual computer-vision frame (x right, y down, z forward); pixel ``(u, v)`` lies in
the image when ``0 <= u <= width - 1`` and ``0 <= v <= height - 1``.

Surfaces implement a small protocol (:class:`Surface`): ``implicit`` (negative inside, positive
on the camera side), ``signed_distance``, ``normal`` (outward), ``closest_point``,
``intersect`` (first hit along rays), ``chart`` (a smooth local parametrisation), ``sample``
and ``mesh`` (a truth mesh). Open surfaces (planes, height fields) face ``+z`` or their given
normal; the cameras must look from that side.

Built-in scenes (:func:`make_scene`) reproduce the paper's experiments with look-alike data:
``octant``, ``car-window``, ``wine-bottle``, plus ``ellipsoid-cap``, ``paraboloid`` and
``saddle``. Their geometry is fixed; ``seed`` drives only the pixel noise and the outliers.

A second set covers every shape class, its geometry varied a little by ``seed`` (sizes, axis
ratios, bump positions, camera jitter, which points are chosen): closed objects seen all
around (``sphere-around``, ``ellipsoid-around`` with a lamp per camera, ``torus``), a
``bottle`` open at the domain's ends, a ``wrap`` patch spanning more than 180 degrees, a
``freeform`` height field (``highlights`` chooses how many) and a ``point-light`` dome. Their
outliers are false highlights on the object (a pixel whose ray meets the truth where the
reflection law's normal is wrong by 15 degrees or more), and their truth records whether it is
closed and its Euler number.
"""

from __future__ import annotations

import copy
import inspect
import json
import math
import zlib
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from scipy.optimize import root

from .errors import SceneError
from .evaluate import FEATURE_AB, FEATURE_AC, FEATURE_BC, FEATURE_FACE, closest_point

if TYPE_CHECKING:
    from .scene import Scene

__all__ = [
    "CameraLight",
    "Cylinder",
    "DirectionalLight",
    "Ellipsoid",
    "Halfspace",
    "Intrinsics",
    "LightModel",
    "MeshSurface",
    "Paraboloid",
    "Plane",
    "PointLight",
    "QuadraticHeightField",
    "SCENES",
    "Saddle",
    "Sphere",
    "Surface",
    "SyntheticScene",
    "as_light",
    "camera_centre",
    "car_window",
    "clip_mesh",
    "corrupt_pixels",
    "ellipsoid_cap",
    "find_highlight",
    "find_highlights",
    "look_at",
    "make_scene",
    "octant",
    "paraboloid",
    "pixel_rays",
    "place_camera",
    "project",
    "reflect",
    "saddle",
    "scene_from_path",
    "scene_from_points",
    "scene_names",
    "spread_points",
    "wine_bottle",
]


# --------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------


def _vec3(value: Any, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SceneError(f"{name}: expected 3 finite numbers, got {value!r}")
    return v


def _unit3(value: Any, name: str) -> np.ndarray:
    v = _vec3(value, name)
    n = float(np.linalg.norm(v))
    if n == 0:
        raise SceneError(f"{name}: must be a non-zero vector, got {value!r}")
    return v / n


def _points(x: Any) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).reshape(-1, 3)


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to the unit vector ``n`` and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def _first_root(a: np.ndarray, b: np.ndarray, c: np.ndarray, t_min: float) -> np.ndarray:
    """Smallest root ``t > t_min`` of ``a t^2 + b t + c = 0`` per element, else ``inf``."""
    a, b, c = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, b, c)))
    out = np.full(a.shape, np.inf)
    scale = np.maximum(np.abs(b), 1e-300)
    quad = np.abs(a) > 1e-14 * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4 * a * c
        ok = quad & (disc >= 0)
        q = -0.5 * (b + np.copysign(np.sqrt(np.where(ok, disc, 0.0)), b))
        r1 = np.where(ok & (a != 0), q / a, np.inf)
        r2 = np.where(ok & (q != 0), c / q, np.inf)
        lin = ~quad & (b != 0)
        r3 = np.where(lin, -c / b, np.inf)
    for r in (r1, r2, r3):
        r = np.where(np.isfinite(r) & (r > t_min), r, np.inf)
        out = np.minimum(out, r)
    return out


def _grid_mesh(grid: np.ndarray, surface: Surface) -> trimesh.Trimesh:
    """Triangulate an ``(nu, nv, 3)`` grid of surface points, facing along ``surface.normal``."""
    nu, nv = grid.shape[:2]
    idx = np.arange(nu * nv).reshape(nu, nv)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    mesh = trimesh.Trimesh(vertices=grid.reshape(-1, 3), faces=faces, process=False)
    return _orient(mesh, surface)


def _orient(mesh: trimesh.Trimesh, surface: Surface) -> trimesh.Trimesh:
    """Flip the triangles whose normal disagrees with the surface's outward normal."""
    faces = np.asarray(mesh.faces).copy()
    tri = np.asarray(mesh.vertices)[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = _dot(fn, surface.normal(tri.mean(axis=1))) < 0
    faces[flip] = faces[flip][:, ::-1]
    return trimesh.Trimesh(vertices=np.asarray(mesh.vertices), faces=faces, process=False)


# --------------------------------------------------------------------------------------------
# Surfaces
# --------------------------------------------------------------------------------------------


class Surface(ABC):
    """A surface with ground truth: implicit function, normal, projection, rays and a mesh.

    ``implicit(x)`` is negative inside and positive outside, where outside is the side the
    normals point to and the cameras look from.

    Attributes:
        closed: Whether the surface bounds a volume (a sphere) or is open (a height field).
    """

    closed: bool = True

    @abstractmethod
    def implicit(self, x: np.ndarray) -> np.ndarray:
        """Implicit function at points ``(N, 3)``: < 0 inside, 0 on, > 0 outside (``(N,)``)."""

    @abstractmethod
    def normal(self, x: np.ndarray) -> np.ndarray:
        """Outward unit normals ``(N, 3)``; at surface points, the surface normal."""

    @abstractmethod
    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest surface points ``(N, 3)`` of points ``(N, 3)``."""

    @abstractmethod
    def intersect(
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        """First hit of rays ``origins + t * directions`` with ``t > t_min``, ``inf`` if none.

        Args:
            origins: Ray origins ``(N, 3)``.
            directions: Ray directions ``(N, 3)`` (any length; ``t`` is in their units).
            t_min: Smallest ``t`` that counts as a hit.

        Returns:
            The ray parameters ``t`` of the first hits, shape ``(N,)``.
        """

    @abstractmethod
    def mesh(self, **options: Any) -> trimesh.Trimesh:
        """A truth mesh with triangles facing outward (options depend on the surface)."""

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance ``(N,)`` to the surface: negative inside, positive outside."""
        x = _points(x)
        d = np.linalg.norm(x - self.closest_point(x), axis=1)
        return np.where(self.implicit(x) < 0, -d, d)

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A smooth local parametrisation ``(u, v) -> point`` around the surface point ``x0``.

        The default projects the tangent plane at ``x0`` onto the surface.
        """
        x0 = np.asarray(x0, dtype=np.float64).reshape(3)
        t1, t2 = _tangent_basis(self.normal(x0[None])[0])

        def point(uv: np.ndarray) -> np.ndarray:
            return self.closest_point((x0 + uv[0] * t1 + uv[1] * t2)[None])[0]

        return point

    def sample(self, count: int, *, seed: int = 0, **mesh_options: Any) -> np.ndarray:
        """``count`` points on the surface, uniform by area over :meth:`mesh`, seeded."""
        pts, _ = trimesh.sample.sample_surface(self.mesh(**mesh_options), int(count), seed=seed)
        return self.closest_point(np.asarray(pts, dtype=np.float64))


class Sphere(Surface):
    """A sphere.

    Args:
        centre: Centre ``(3,)``.
        radius: Radius (> 0).
    """

    closed = True

    def __init__(self, centre: Sequence[float], radius: float) -> None:
        self.centre = _vec3(centre, "centre")
        if not (np.isfinite(radius) and radius > 0):
            raise SceneError(f"radius: must be a positive number, got {radius!r}")
        self.radius = float(radius)

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return np.linalg.norm(_points(x) - self.centre, axis=1) - self.radius

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.implicit(x)

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return _normalize(_points(x) - self.centre)

    def closest_point(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.centre + self.radius * self.normal(x)

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        oc = _points(origins) - self.centre
        d = _points(directions)
        return _first_root(_dot(d, d), 2 * _dot(d, oc), _dot(oc, oc) - self.radius**2, t_min)

    def mesh(self, *, subdivisions: int = 5) -> trimesh.Trimesh:
        """Icosphere with ``subdivisions`` levels (5: 20480 triangles)."""
        m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=self.radius)
        return trimesh.Trimesh(vertices=m.vertices + self.centre, faces=m.faces, process=False)


class Ellipsoid(Surface):
    """An axis-aligned ellipsoid ``sum(((x - centre) / radii)^2) = 1``.

    Args:
        centre: Centre ``(3,)``.
        radii: Semi-axes along x, y and z (> 0).
    """

    closed = True

    def __init__(self, centre: Sequence[float], radii: Sequence[float]) -> None:
        self.centre = _vec3(centre, "centre")
        self.radii = _vec3(radii, "radii")
        if np.any(self.radii <= 0):
            raise SceneError(f"radii: must be positive, got {list(radii)!r}")

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return np.linalg.norm((_points(x) - self.centre) / self.radii, axis=1) - 1.0

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit gradient of the quadratic form: the surface normal at surface points."""
        return _normalize((_points(x) - self.centre) / self.radii**2)

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest points, by bisection on the Lagrange multiplier (Eberly).

        Exact to rounding for points outside and for most points inside; points on the inner
        medial disc (a zero coordinate along the smallest axis) get an approximate answer.
        """
        y = _points(x) - self.centre
        r2 = self.radii**2
        ay = np.abs(y)
        lo = np.full(len(y), -float(r2.min()))
        hi = np.maximum(float(self.radii.max()) * np.linalg.norm(y, axis=1), 1e-300)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            f = np.sum((self.radii * ay / (mid[:, None] + r2)) ** 2, axis=1) - 1.0
            pos = f > 0
            lo = np.where(pos, mid, lo)
            hi = np.where(pos, hi, mid)
        t = 0.5 * (lo + hi)
        p = r2 * y / (t[:, None] + r2)
        # Put the result exactly on the surface (removes the bisection's last rounding).
        p /= np.linalg.norm(p / self.radii, axis=1, keepdims=True)
        return self.centre + p

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Local chart through the unit sphere: smooth and exactly on the ellipsoid."""
        s0 = (np.asarray(x0, dtype=np.float64).reshape(3) - self.centre) / self.radii
        s0 /= np.linalg.norm(s0)
        t1, t2 = _tangent_basis(s0)

        def point(uv: np.ndarray) -> np.ndarray:
            s = s0 + uv[0] * t1 + uv[1] * t2
            return self.centre + self.radii * s / np.linalg.norm(s)

        return point

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o = (_points(origins) - self.centre) / self.radii
        d = _points(directions) / self.radii
        return _first_root(_dot(d, d), 2 * _dot(d, o), _dot(o, o) - 1.0, t_min)

    def mesh(self, *, subdivisions: int = 5) -> trimesh.Trimesh:
        """Scaled icosphere with ``subdivisions`` levels; vertices lie on the ellipsoid."""
        m = trimesh.creation.icosphere(subdivisions=subdivisions)
        v = np.asarray(m.vertices)
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
        return trimesh.Trimesh(vertices=self.centre + self.radii * v, faces=m.faces,
                               process=False)


class Cylinder(Surface):
    """An infinite circular cylinder; its mesh covers an axial ``extent`` (and angle range).

    Args:
        point: A point on the axis ``(3,)``.
        direction: Axis direction ``(3,)``.
        radius: Radius (> 0).
        reference: Direction of angle 0 around the axis (projected orthogonal to the axis);
            angles grow from ``reference`` toward ``direction x reference``.
        extent: Axial range ``(lo, hi)`` of the mesh, measured from ``point``.
        angles: Angle range ``(lo, hi)`` in radians of the mesh; the full circle by default.
    """

    closed = True

    def __init__(
        self,
        point: Sequence[float],
        direction: Sequence[float],
        radius: float,
        *,
        reference: Sequence[float] | None = None,
        extent: tuple[float, float] = (-1.0, 1.0),
        angles: tuple[float, float] | None = None,
    ) -> None:
        self.point = _vec3(point, "point")
        self.axis = _unit3(direction, "direction")
        if not (np.isfinite(radius) and radius > 0):
            raise SceneError(f"radius: must be a positive number, got {radius!r}")
        self.radius = float(radius)
        if reference is None:
            e1, _ = _tangent_basis(self.axis)
        else:
            ref = _vec3(reference, "reference")
            e1 = ref - np.dot(ref, self.axis) * self.axis
            if np.linalg.norm(e1) < 1e-12:
                raise SceneError(f"reference: must not be parallel to the axis, got {reference!r}")
            e1 /= np.linalg.norm(e1)
        self.e1 = e1
        self.e2 = np.cross(self.axis, e1)
        self.extent = (float(extent[0]), float(extent[1]))
        self.angles = None if angles is None else (float(angles[0]), float(angles[1]))

    def at(self, angle: Any, height: Any) -> np.ndarray:
        """Surface points at angles (radians) and axial heights, broadcast, shape ``(..., 3)``."""
        angle = np.asarray(angle, dtype=np.float64)[..., None]
        height = np.asarray(height, dtype=np.float64)[..., None]
        return (self.point + height * self.axis
                + self.radius * (np.cos(angle) * self.e1 + np.sin(angle) * self.e2))

    def _radial(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = _points(x) - self.point
        h = y @ self.axis
        return y - h[:, None] * self.axis, h

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return np.linalg.norm(self._radial(x)[0], axis=1) - self.radius

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.implicit(x)

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return _normalize(self._radial(x)[0])

    def closest_point(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        radial, h = self._radial(x)
        return self.point + h[:, None] * self.axis + self.radius * _normalize(radial)

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o, _ = self._radial(origins)
        d = _points(directions)
        d = d - (d @ self.axis)[:, None] * self.axis
        return _first_root(_dot(d, d), 2 * _dot(d, o), _dot(o, o) - self.radius**2, t_min)

    def mesh(
        self,
        *,
        sections: int = 256,
        extent: tuple[float, float] | None = None,
        angles: tuple[float, float] | None = None,
    ) -> trimesh.Trimesh:
        """Open tube: ``sections`` segments around (over ``angles``), rings to match.

        Args:
            sections: Number of segments over the angle range.
            extent: Axial range, default the cylinder's ``extent``.
            angles: Angle range, default the cylinder's ``angles`` or the full circle.
        """
        lo, hi = extent or self.extent
        a0, a1 = angles or self.angles or (0.0, 2 * math.pi)
        full = angles is None and self.angles is None
        step = self.radius * (a1 - a0) / sections
        rings = max(int(math.ceil((hi - lo) / step)), 1)
        ang = np.linspace(a0, a1, sections + 1)
        if full:
            ang = ang[:-1]
        hgt = np.linspace(lo, hi, rings + 1)
        grid = self.at(ang[:, None], hgt[None, :])
        if not full:
            return _grid_mesh(grid, self)
        # Close the seam: wrap the angle index.
        nu, nv = len(ang), len(hgt)
        idx = np.arange(nu * nv).reshape(nu, nv)
        nxt = np.roll(idx, -1, axis=0)
        a, b = idx[:, :-1].ravel(), nxt[:, :-1].ravel()
        c, d = nxt[:, 1:].ravel(), idx[:, 1:].ravel()
        faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
        m = trimesh.Trimesh(vertices=grid.reshape(-1, 3), faces=faces, process=False)
        return _orient(m, self)


class Plane(Surface):
    """A plane through ``point`` with outward ``normal``; its mesh is a square of side ``size``.

    Args:
        point: A point on the plane ``(3,)``.
        normal: Outward normal ``(3,)`` (toward the cameras).
        size: Side of the square mesh centred at ``point``.
    """

    closed = False

    def __init__(self, point: Sequence[float], normal: Sequence[float], *, size: float = 2.0
                 ) -> None:
        self.point = _vec3(point, "point")
        self.n = _unit3(normal, "normal")
        self.size = float(size)

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return (_points(x) - self.point) @ self.n

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.implicit(x)

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return np.tile(self.n, (len(_points(x)), 1))

    def closest_point(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        return x - self.implicit(x)[:, None] * self.n

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o, d = _points(origins), _points(directions)
        dn = d @ self.n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -self.implicit(o) / dn
        return np.where(np.isfinite(t) & (t > t_min), t, np.inf)

    def mesh(self, *, resolution: int = 64, size: float | None = None) -> trimesh.Trimesh:
        """Square of side ``size`` (default the plane's) with ``resolution`` cells a side."""
        s = 0.5 * (size or self.size)
        t1, t2 = _tangent_basis(self.n)
        g = np.linspace(-s, s, resolution + 1)
        grid = self.point + g[:, None, None] * t1 + g[None, :, None] * t2
        return _grid_mesh(grid, self)


class QuadraticHeightField(Surface):
    """An open surface ``z = z0 + g.(p - p0) + 1/2 (p - p0)^T H (p - p0)``, ``p = (x, y)``.

    The outward normal points up (``+z``): cameras look from above. The surface is defined
    everywhere; ``region`` bounds its mesh, its samples and its corners.

    Args:
        origin: ``p0 = (x0, y0)``.
        z0: Height at ``p0``.
        slope: Gradient ``g`` at ``p0``.
        hessian: Symmetric 2x2 matrix ``H``.
        region: ``(xmin, xmax, ymin, ymax)``.
    """

    closed = False

    def __init__(
        self,
        origin: Sequence[float],
        z0: float,
        slope: Sequence[float],
        hessian: Sequence[Sequence[float]],
        *,
        region: Sequence[float],
    ) -> None:
        self.origin = np.asarray(origin, dtype=np.float64).reshape(2)
        self.z0 = float(z0)
        self.slope = np.asarray(slope, dtype=np.float64).reshape(2)
        h = np.asarray(hessian, dtype=np.float64).reshape(2, 2)
        self.hessian = 0.5 * (h + h.T)
        self.region = tuple(float(v) for v in region)
        if len(self.region) != 4 or not (self.region[0] < self.region[1]
                                         and self.region[2] < self.region[3]):
            raise SceneError(f"region: expected (xmin, xmax, ymin, ymax), got {region!r}")

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Heights ``(N,)`` at plane points ``(N, 2)``."""
        w = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - self.origin
        return self.z0 + w @ self.slope + 0.5 * _dot(w @ self.hessian, w)

    def gradient(self, xy: np.ndarray) -> np.ndarray:
        """Gradient ``(N, 2)`` of the height at plane points ``(N, 2)``."""
        w = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - self.origin
        return self.slope + w @ self.hessian

    def lift(self, xy: np.ndarray) -> np.ndarray:
        """Surface points ``(N, 3)`` above plane points ``(N, 2)``."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([xy, self.height(xy)])

    def corners(self) -> np.ndarray:
        """The surface points above the four corners of ``region``, shape ``(4, 3)``."""
        x0, x1, y0, y1 = self.region
        return self.lift([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        return x[:, 2] - self.height(x[:, :2])

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        g = self.gradient(x[:, :2])
        return _normalize(np.column_stack([-g, np.ones(len(x))]))

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest points by damped Newton iterations on the height-field parameters."""
        x = _points(x)
        u = x[:, :2].copy()
        eye = np.eye(2)
        for _ in range(60):
            f = self.height(u)
            g = self.gradient(u)
            res = f - x[:, 2]
            grad = (u - x[:, :2]) + res[:, None] * g
            hess = eye + g[:, :, None] * g[:, None, :] + res[:, None, None] * self.hessian
            # Fall back to Gauss-Newton where the Hessian is not positive definite.
            det = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] * hess[:, 1, 0]
            bad = (det <= 1e-12) | (hess[:, 0, 0] <= 0)
            hess[bad] = eye + g[bad, :, None] * g[bad, None, :]
            step = np.linalg.solve(hess, grad[:, :, None])[:, :, 0]
            u = u - step
            if np.max(np.abs(step)) < 1e-15:
                break
        return self.lift(u)

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Local chart ``(u, v) -> (x0 + u, y0 + v, f(...))``: exactly on the surface."""
        xy0 = np.asarray(x0, dtype=np.float64).reshape(3)[:2]

        def point(uv: np.ndarray) -> np.ndarray:
            return self.lift(xy0 + np.asarray(uv))[0]

        return point

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o, d = _points(origins), _points(directions)
        w = o[:, :2] - self.origin
        e = d[:, :2]
        he = e @ self.hessian
        a = -0.5 * _dot(he, e)
        b = d[:, 2] - e @ self.slope - _dot(w, he)
        c = o[:, 2] - self.z0 - w @ self.slope - 0.5 * _dot(w @ self.hessian, w)
        return _first_root(a, b, c, t_min)

    def mesh(self, *, resolution: int = 128) -> trimesh.Trimesh:
        """Grid over ``region`` with ``resolution`` cells along its longer side."""
        x0, x1, y0, y1 = self.region
        step = max(x1 - x0, y1 - y0) / resolution
        nx = max(int(math.ceil((x1 - x0) / step - 1e-9)), 1)
        ny = max(int(math.ceil((y1 - y0) / step - 1e-9)), 1)
        xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
        xy = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
        grid = self.lift(xy.reshape(-1, 2)).reshape(nx + 1, ny + 1, 3)
        return _grid_mesh(grid, self)


class Paraboloid(QuadraticHeightField):
    """Elliptic paraboloid ``z = apex_z + a (x - apex_x)^2 + b (y - apex_y)^2``.

    Negative ``a`` and ``b`` give a dome (convex toward the cameras above), positive a bowl.

    Args:
        apex: The apex ``(3,)``.
        a: Coefficient along x.
        b: Coefficient along y.
        region: ``(xmin, xmax, ymin, ymax)``; default the apex +- 0.5.
    """

    def __init__(self, apex: Sequence[float], a: float, b: float, *,
                 region: Sequence[float] | None = None) -> None:
        apex = _vec3(apex, "apex")
        if region is None:
            region = (apex[0] - 0.5, apex[0] + 0.5, apex[1] - 0.5, apex[1] + 0.5)
        super().__init__(apex[:2], apex[2], (0.0, 0.0), np.diag([2 * a, 2 * b]), region=region)
        self.apex, self.a, self.b = apex, float(a), float(b)


class Saddle(QuadraticHeightField):
    """Hyperbolic paraboloid ``z = centre_z + k ((x - centre_x)^2 - (y - centre_y)^2)``.

    Args:
        centre: The saddle point ``(3,)``.
        k: Curvature coefficient.
        region: ``(xmin, xmax, ymin, ymax)``; default the centre +- 0.5.
    """

    def __init__(self, centre: Sequence[float], k: float, *,
                 region: Sequence[float] | None = None) -> None:
        centre = _vec3(centre, "centre")
        if region is None:
            region = (centre[0] - 0.5, centre[0] + 0.5, centre[1] - 0.5, centre[1] + 0.5)
        super().__init__(centre[:2], centre[2], (0.0, 0.0), np.diag([2 * k, -2 * k]),
                         region=region)
        self.centre, self.k = centre, float(k)


class MeshSurface(Surface):
    """Any triangle mesh, closed or open, as a surface.

    Normals are the face normals (angle-weighted pseudo-normals on edges and vertices, so the
    sign of the distance is right everywhere). A closed mesh with negative volume is turned
    inside out; an open mesh keeps its winding (use ``flip`` to turn it toward the cameras).

    Args:
        mesh: The mesh (copied).
        flip: Reverse the winding after the automatic orientation.
    """

    def __init__(self, mesh: trimesh.Trimesh, *, flip: bool = False) -> None:
        m = trimesh.Trimesh(vertices=np.asarray(mesh.vertices, dtype=np.float64),
                            faces=np.asarray(mesh.faces), process=True)
        if len(m.faces) == 0:
            raise SceneError("mesh: has no faces")
        self.closed = bool(m.is_watertight)
        if self.closed and m.volume < 0:
            m.invert()
        if flip:
            m.invert()
        self._mesh = m
        faces = np.asarray(m.faces)
        fn = np.asarray(m.face_normals)
        self._face_normals = fn
        # Angle-weighted vertex pseudo-normals.
        vn = np.zeros((len(m.vertices), 3))
        np.add.at(vn, faces, fn[:, None, :] * np.asarray(m.face_angles)[:, :, None])
        self._vertex_normals = _normalize(vn)
        # Edge pseudo-normals: the sum of the normals of the faces that share the edge.
        nv = len(m.vertices)
        edges = np.sort(faces[:, [[0, 1], [0, 2], [1, 2]]], axis=2).reshape(-1, 2)
        keys = edges[:, 0] * nv + edges[:, 1]
        uniq, inv = np.unique(keys, return_inverse=True)
        en = np.zeros((len(uniq), 3))
        np.add.at(en, inv, np.repeat(fn, 3, axis=0))
        self._edge_keys = uniq
        self._edge_normals = _normalize(en)

    def _query(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = _points(x)
        cp, _, face, feature = closest_point(self._mesh, x)
        faces = np.asarray(self._mesh.faces)[face]
        n = self._face_normals[face].copy()
        nv = len(self._mesh.vertices)
        for feat, (i, j) in ((FEATURE_AB, (0, 1)), (FEATURE_AC, (0, 2)), (FEATURE_BC, (1, 2))):
            m = feature == feat
            if np.any(m):
                e = np.sort(faces[m][:, [i, j]], axis=1)
                n[m] = self._edge_normals[np.searchsorted(self._edge_keys, e[:, 0] * nv + e[:, 1])]
        corner = (feature != FEATURE_FACE) & ~np.isin(feature, (FEATURE_AB, FEATURE_AC,
                                                                FEATURE_BC))
        if np.any(corner):
            col = np.select([feature[corner] == 0, feature[corner] == 1], [0, 1], 2)
            n[corner] = self._vertex_normals[faces[corner, col]]
        return cp, n

    def implicit(self, x: np.ndarray) -> np.ndarray:
        """Signed distance to the mesh (sign from the pseudo-normal of the closest feature)."""
        x = _points(x)
        cp, n = self._query(x)
        d = np.linalg.norm(x - cp, axis=1)
        return np.where(_dot(x - cp, n) < 0, -d, d)

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.implicit(x)

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Normal of the closest face (pseudo-normal when the closest point is on an edge)."""
        return self._query(x)[1]

    def closest_point(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return closest_point(self._mesh, _points(x))[0]

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        tri = np.asarray(self._mesh.triangles)
        a = tri[:, 0]
        e1, e2 = tri[:, 1] - a, tri[:, 2] - a
        out = np.full(len(_points(origins)), np.inf)
        for i, (o, d) in enumerate(zip(_points(origins), _points(directions), strict=True)):
            p = np.cross(d, e2)
            det = _dot(e1, p)
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = o - a
            u = _dot(s, p) * inv
            q = np.cross(s, e1)
            v = (q @ d) * inv
            t = _dot(e2, q) * inv
            hit = ok & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12) & (t > t_min)
            if np.any(hit):
                out[i] = t[hit].min()
        return out

    def mesh(self) -> trimesh.Trimesh:
        """A copy of the (oriented) mesh."""
        return self._mesh.copy()

    def sample(self, count: int, *, seed: int = 0) -> np.ndarray:  # noqa: D102
        pts, _ = trimesh.sample.sample_surface(self._mesh, int(count), seed=seed)
        return np.asarray(pts, dtype=np.float64)


def _march(
    f: Callable[[np.ndarray], np.ndarray],
    origins: np.ndarray,
    directions: np.ndarray,
    t0: np.ndarray,
    t1: np.ndarray,
    *,
    step: float,
) -> np.ndarray:
    """First sign change of ``f`` along rays between ``t0`` and ``t1``, refined by bisection.

    ``f`` maps points ``(N, 3)`` to values ``(N,)``. The rays are sampled every ``step`` (at
    most 4096 samples); a crossing thinner than a step (a grazing ray) can be missed.

    Returns:
        The ray parameters of the first crossings ``(N,)``, ``inf`` where there is none.
    """
    o, d = _points(origins), _points(directions)
    out = np.full(len(o), np.inf)
    todo = np.flatnonzero(np.isfinite(t0) & np.isfinite(t1) & (t1 > t0))
    if len(todo) == 0:
        return out
    span = float(np.max(t1[todo] - t0[todo]))
    k = int(min(max(math.ceil(span / step), 2), 4096)) + 1
    s = np.linspace(0.0, 1.0, k)
    ts = t0[todo, None] + s[None, :] * (t1[todo] - t0[todo])[:, None]
    pts = o[todo, None, :] + ts[..., None] * d[todo, None, :]
    val = f(pts.reshape(-1, 3)).reshape(len(todo), k)
    change = (np.sign(val[:, :-1]) != np.sign(val[:, 1:])) | (val[:, :-1] == 0)
    has = change.any(axis=1)
    first = np.argmax(change, axis=1)
    rows = np.flatnonzero(has)
    if len(rows) == 0:
        return out
    lo = ts[rows, first[rows]]
    hi = ts[rows, first[rows] + 1]
    flo = val[rows, first[rows]]
    idx = todo[rows]
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        fm = f(o[idx] + mid[:, None] * d[idx])
        same = np.sign(fm) == np.sign(flo)
        lo = np.where(same, mid, lo)
        flo = np.where(same, fm, flo)
        hi = np.where(same, hi, mid)
    out[idx] = np.where(flo == 0, lo, 0.5 * (lo + hi))
    return out


def _box_interval(origins: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameters ``(t0, t1)`` where rays are inside the box ``[lo, hi]`` (empty: t0 > t1)."""
    o, d = _points(origins), _points(directions)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    tmin = np.where(np.isnan(ta), -np.inf, np.minimum(ta, tb))
    tmax = np.where(np.isnan(ta), np.inf, np.maximum(ta, tb))
    # Rays parallel to a slab: inside for all t or never.
    par = d == 0
    outside = par & ((o < lo) | (o > hi))
    tmin = np.where(par, -np.inf, tmin)
    tmax = np.where(par, np.inf, tmax)
    t0 = tmin.max(axis=1)
    t1 = np.where(outside.any(axis=1), -np.inf, tmax.min(axis=1))
    return t0, t1


class Torus(Surface):
    """A ring torus: the points at distance ``minor`` from a circle of radius ``major``.

    Args:
        centre: Centre ``(3,)``.
        axis: Axis of symmetry ``(3,)`` (the hole runs along it).
        major: Radius of the tube's centre circle (> minor).
        minor: Radius of the tube (> 0).
    """

    closed = True

    def __init__(self, centre: Sequence[float], axis: Sequence[float], major: float,
                 minor: float) -> None:
        self.centre = _vec3(centre, "centre")
        self.axis = _unit3(axis, "axis")
        if not (np.isfinite(minor) and np.isfinite(major) and 0 < minor < major):
            raise SceneError(f"minor, major: need 0 < minor < major, got {minor!r}, {major!r}")
        self.major, self.minor = float(major), float(minor)
        self.e1, self.e2 = _tangent_basis(self.axis)

    def _local(self, x: np.ndarray) -> np.ndarray:
        y = _points(x) - self.centre
        return np.column_stack([y @ self.e1, y @ self.e2, y @ self.axis])

    def at(self, u: Any, v: Any) -> np.ndarray:
        """Points at angle ``u`` around the axis and ``v`` around the tube, shape ``(..., 3)``."""
        u = np.asarray(u, dtype=np.float64)[..., None]
        v = np.asarray(v, dtype=np.float64)[..., None]
        ring = self.major + self.minor * np.cos(v)
        return (self.centre + ring * (np.cos(u) * self.e1 + np.sin(u) * self.e2)
                + self.minor * np.sin(v) * self.axis)

    def _angles(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = self._local(x)
        u = np.arctan2(q[:, 1], q[:, 0])
        v = np.arctan2(q[:, 2], np.hypot(q[:, 0], q[:, 1]) - self.major)
        return u, v

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        q = self._local(x)
        return np.hypot(np.hypot(q[:, 0], q[:, 1]) - self.major, q[:, 2]) - self.minor

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        return self.implicit(x)

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        u, v = self._angles(x)
        radial = np.cos(u)[:, None] * self.e1 + np.sin(u)[:, None] * self.e2
        return np.cos(v)[:, None] * radial + np.sin(v)[:, None] * self.axis

    def closest_point(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        u, v = self._angles(x)
        return self.at(u, v)

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Chart by the two angles around ``x0``: smooth and exactly on the torus."""
        u0, v0 = (float(a[0]) for a in self._angles(np.asarray(x0).reshape(1, 3)))

        def point(uv: np.ndarray) -> np.ndarray:
            return self.at(u0 + uv[0], v0 + uv[1])

        return point

    def intersect(
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        """First hits: real roots of the quartic, polished by Newton steps on the distance."""
        o = self._local(origins)
        d = self._local(_points(directions) + self.centre)
        R2, r2 = self.major**2, self.minor**2
        A = _dot(d, d)
        B = 2 * _dot(o, d)
        K = _dot(o, o) + R2 - r2
        coeffs = np.column_stack([
            A * A, 2 * A * B, B * B + 2 * A * K - 4 * R2 * (d[:, 0] ** 2 + d[:, 1] ** 2),
            2 * B * K - 8 * R2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]),
            K * K - 4 * R2 * (o[:, 0] ** 2 + o[:, 1] ** 2),
        ])
        out = np.full(len(o), np.inf)
        for i in range(len(o)):
            roots = np.roots(coeffs[i])
            scale = max(1.0, float(np.abs(roots).max(initial=0.0)))
            real = np.sort(roots[np.abs(roots.imag) <= 1e-6 * scale].real)
            for t in real:
                for _ in range(8):  # Newton on the exact distance along the ray
                    p = o[i] + t * d[i]
                    rho = math.hypot(p[0], p[1])
                    dist = math.hypot(rho - self.major, p[2])
                    if dist == 0 or rho == 0:
                        break
                    g = np.array([p[0] / rho * (rho - self.major), p[1] / rho * (rho - self.major),
                                  p[2]]) / dist
                    slope = float(g @ d[i])
                    if abs(slope) < 1e-9 * math.sqrt(A[i]):
                        break
                    t -= (dist - self.minor) / slope
                if t > t_min:
                    out[i] = t
                    break
        return out

    def mesh(self, *, sections: int = 192, tube: int = 64) -> trimesh.Trimesh:
        """Watertight grid mesh: ``sections`` around the axis, ``tube`` around the tube."""
        u = np.linspace(0, 2 * math.pi, sections, endpoint=False)
        v = np.linspace(0, 2 * math.pi, tube, endpoint=False)
        grid = self.at(u[:, None], v[None, :])
        idx = np.arange(sections * tube).reshape(sections, tube)
        nu, nv = np.roll(idx, -1, axis=0), np.roll(idx, -1, axis=1)
        nuv = np.roll(nu, -1, axis=1)
        faces = np.concatenate([np.stack([idx, nu, nuv], -1).reshape(-1, 3),
                                np.stack([idx, nuv, nv], -1).reshape(-1, 3)])
        m = trimesh.Trimesh(vertices=grid.reshape(-1, 3), faces=faces, process=False)
        return _orient(m, self)


class Revolution(Surface):
    """A bottle-like surface of revolution: radius ``neck + (body - neck) (1 - tanh s) / 2``.

    With ``s = (height - shoulder) / width``, the height measured along ``axis`` from ``base``:
    a body of radius ``body`` below the shoulder, a neck of radius ``neck`` above it, joined
    smoothly. The surface is unbounded along the axis; its mesh spans ``extent``.

    Args:
        base: A point on the axis ``(3,)`` (height 0).
        axis: Axis direction ``(3,)`` (toward the neck).
        body: Radius of the body (> neck).
        neck: Radius of the neck (> 0).
        shoulder: Height of the middle of the shoulder.
        width: Length scale of the shoulder (> 0).
        extent: Heights ``(lo, hi)`` the mesh spans.
    """

    closed = True

    def __init__(self, base: Sequence[float], axis: Sequence[float], *, body: float,
                 neck: float, shoulder: float, width: float,
                 extent: tuple[float, float] = (-1.0, 1.0)) -> None:
        self.base = _vec3(base, "base")
        self.axis = _unit3(axis, "axis")
        if not (0 < neck < body and width > 0):
            raise SceneError(f"body, neck, width: need 0 < neck < body and width > 0, got "
                             f"{body!r}, {neck!r}, {width!r}")
        self.body, self.neck = float(body), float(neck)
        self.shoulder, self.width = float(shoulder), float(width)
        self.extent = (float(extent[0]), float(extent[1]))
        self.e1, self.e2 = _tangent_basis(self.axis)

    def radius(self, h: np.ndarray) -> np.ndarray:
        """Radius at heights ``h``."""
        s = (np.asarray(h, dtype=np.float64) - self.shoulder) / self.width
        return self.neck + (self.body - self.neck) * 0.5 * (1 - np.tanh(s))

    def _derivatives(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        th = np.tanh((h - self.shoulder) / self.width)
        sech2 = 1 - th * th
        k = 0.5 * (self.body - self.neck) / self.width
        return -k * sech2, 2 * k / self.width * sech2 * th

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        y = _points(x) - self.base
        h = y @ self.axis
        radial = y - h[:, None] * self.axis
        rho = np.linalg.norm(radial, axis=1)
        e = np.where(rho[:, None] > 0, radial / np.where(rho > 0, rho, 1.0)[:, None], self.e1)
        return h, rho, e

    def at(self, angle: Any, height: Any) -> np.ndarray:
        """Surface points at angles and heights, broadcast, shape ``(..., 3)``."""
        a = np.asarray(angle, dtype=np.float64)[..., None]
        h = np.asarray(height, dtype=np.float64)[..., None]
        return (self.base + h * self.axis
                + self.radius(h) * (np.cos(a) * self.e1 + np.sin(a) * self.e2))

    def implicit(self, x: np.ndarray) -> np.ndarray:
        """``rho - radius(h)``: the sign of the distance, not the distance itself."""
        h, rho, _ = self._split(x)
        return rho - self.radius(h)

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit gradient of :meth:`implicit`: the surface normal at surface points."""
        h, _, e = self._split(x)
        d1, _ = self._derivatives(h)
        return _normalize(e - d1[:, None] * self.axis)

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest points: the nearest point of the profile in the meridian half-plane.

        A dense scan over the heights picks the start, Newton iterations finish it.
        """
        h0, rho, e = self._split(x)
        offs = np.linspace(-2.0, 2.0, 161) * (self.body + self.width)
        hs = h0[:, None] + offs[None, :]
        g = (rho[:, None] - self.radius(hs)) ** 2 + (hs - h0[:, None]) ** 2
        h = hs[np.arange(len(hs)), np.argmin(g, axis=1)]
        for _ in range(60):
            r = self.radius(h)
            d1, d2 = self._derivatives(h)
            grad = -(rho - r) * d1 + (h - h0)
            hess = d1 * d1 - (rho - r) * d2 + 1.0
            step = grad / np.where(hess > 0.1, hess, 0.1)
            h = h - step
            if np.max(np.abs(step)) < 1e-15:
                break
        return self.base + h[:, None] * self.axis + self.radius(h)[:, None] * e

    def signed_distance(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        d = np.linalg.norm(x - self.closest_point(x), axis=1)
        return np.where(self.implicit(x) < 0, -d, d)

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Chart by angle and height around ``x0``: smooth and exactly on the surface."""
        h0, _, e = self._split(np.asarray(x0).reshape(1, 3))
        a0 = math.atan2(float(e[0] @ self.e2), float(e[0] @ self.e1))

        def point(uv: np.ndarray) -> np.ndarray:
            return self.at(a0 + uv[0], h0[0] + uv[1] * self.body)

        return point

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o, d = _points(origins), _points(directions)
        # Only the inside of the cylinder of radius ``body`` can hold a crossing.
        hull = Cylinder(self.base, self.axis, self.body * (1 + 1e-6))
        oc, _ = hull._radial(o)
        dc = d - (d @ self.axis)[:, None] * self.axis
        a, b, c = _dot(dc, dc), 2 * _dot(dc, oc), _dot(oc, oc) - hull.radius**2
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = np.sqrt(np.where(b * b - 4 * a * c >= 0, b * b - 4 * a * c, np.nan))
            t0 = np.where(a > 0, (-b - disc) / (2 * a), -np.inf)
            t1 = np.where(a > 0, (-b + disc) / (2 * a), np.inf)
        t0 = np.maximum(np.nan_to_num(t0, nan=np.inf), t_min)
        t1 = np.nan_to_num(t1, nan=-np.inf)
        norm = np.linalg.norm(d, axis=1).max(initial=1.0)
        return _march(self.implicit, o, d, t0, t1, step=0.01 * self.neck / norm)

    def mesh(self, *, sections: int = 128, extent: tuple[float, float] | None = None
             ) -> trimesh.Trimesh:
        """Open tube over ``extent``: ``sections`` around, rings about as fine along the axis."""
        lo, hi = extent or self.extent
        step = math.pi * (self.body + self.neck) / sections
        rings = min(max(int(math.ceil((hi - lo) / step)), 1), 4 * sections)
        ang = np.linspace(0, 2 * math.pi, sections, endpoint=False)
        hgt = np.linspace(lo, hi, rings + 1)
        grid = self.at(ang[:, None], hgt[None, :])
        idx = np.arange(sections * (rings + 1)).reshape(sections, rings + 1)
        nxt = np.roll(idx, -1, axis=0)
        a, b = idx[:, :-1].ravel(), nxt[:, :-1].ravel()
        c, d = nxt[:, 1:].ravel(), idx[:, 1:].ravel()
        faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
        m = trimesh.Trimesh(vertices=grid.reshape(-1, 3), faces=faces, process=False)
        return _orient(m, self)


class FreeformHeightField(Surface):
    """An open surface ``z = z0 + waves + bumps - dome``, facing ``+z``.

    ``waves`` are rows ``(amplitude, kx, ky, phase)`` adding ``a sin(kx x + ky y + phase)``;
    ``bumps`` are rows ``(amplitude, cx, cy, sigma)`` adding
    ``a exp(-((x - cx)^2 + (y - cy)^2) / (2 sigma^2))``; ``dome = (dx, dy)`` subtracts
    ``dx x^2 + dy y^2``. ``region`` bounds the mesh and the samples; :meth:`intersect` looks for
    hits over the region grown by half its size on each side.

    Args:
        z0: Base height.
        waves: Sine terms ``(K, 4)``.
        bumps: Gaussian terms ``(B, 4)``.
        dome: Quadratic coefficients ``(dx, dy)``.
        region: ``(xmin, xmax, ymin, ymax)``.
    """

    closed = False

    def __init__(self, *, z0: float = 0.0, waves: Any = (), bumps: Any = (),
                 dome: Sequence[float] = (0.0, 0.0), region: Sequence[float]) -> None:
        self.z0 = float(z0)
        self.waves = np.asarray(waves, dtype=np.float64).reshape(-1, 4)
        self.bumps = np.asarray(bumps, dtype=np.float64).reshape(-1, 4)
        if np.any(self.bumps[:, 3] <= 0):
            raise SceneError("bumps: every sigma must be positive")
        self.dome = np.asarray(dome, dtype=np.float64).reshape(2)
        self.region = tuple(float(v) for v in region)
        if len(self.region) != 4 or not (self.region[0] < self.region[1]
                                         and self.region[2] < self.region[3]):
            raise SceneError(f"region: expected (xmin, xmax, ymin, ymax), got {region!r}")

    def _terms(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height ``(N,)``, gradient ``(N, 2)`` and Hessian ``(N, 2, 2)``."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x, y = p[:, 0], p[:, 1]
        h = self.z0 - self.dome[0] * x * x - self.dome[1] * y * y
        g = np.column_stack([-2 * self.dome[0] * x, -2 * self.dome[1] * y])
        H = np.zeros((len(p), 2, 2))
        H[:, 0, 0] = -2 * self.dome[0]
        H[:, 1, 1] = -2 * self.dome[1]
        for a, kx, ky, ph in self.waves:
            arg = kx * x + ky * y + ph
            s, c = a * np.sin(arg), a * np.cos(arg)
            k = np.array([kx, ky])
            h = h + s
            g = g + c[:, None] * k
            H = H - s[:, None, None] * np.outer(k, k)
        for a, cx, cy, sig in self.bumps:
            dx, dy = x - cx, y - cy
            e = a * np.exp(-(dx * dx + dy * dy) / (2 * sig * sig))
            w = np.column_stack([dx, dy]) / (sig * sig)
            h = h + e
            g = g - e[:, None] * w
            H = H + e[:, None, None] * (w[:, :, None] * w[:, None, :]
                                        - np.eye(2) / (sig * sig))
        return h, g, H

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Heights ``(N,)`` at plane points ``(N, 2)``."""
        return self._terms(xy)[0]

    def lift(self, xy: np.ndarray) -> np.ndarray:
        """Surface points ``(N, 3)`` above plane points ``(N, 2)``."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([xy, self.height(xy)])

    def corners(self) -> np.ndarray:
        """The surface points above the four corners of ``region``, shape ``(4, 3)``."""
        x0, x1, y0, y1 = self.region
        return self.lift([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    def implicit(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        return x[:, 2] - self.height(x[:, :2])

    def normal(self, x: np.ndarray) -> np.ndarray:  # noqa: D102
        x = _points(x)
        g = self._terms(x[:, :2])[1]
        return _normalize(np.column_stack([-g, np.ones(len(x))]))

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest points by damped Newton iterations on the height-field parameters.

        Exact for points within the surface's smallest radius of curvature (where the
        closest point is unique), which covers every use here.
        """
        x = _points(x)
        u = x[:, :2].copy()
        eye = np.eye(2)
        for _ in range(100):
            f, g, H = self._terms(u)
            res = f - x[:, 2]
            grad = (u - x[:, :2]) + res[:, None] * g
            hess = eye + g[:, :, None] * g[:, None, :] + res[:, None, None] * H
            det = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] * hess[:, 1, 0]
            bad = (det <= 1e-12) | (hess[:, 0, 0] <= 0)
            hess[bad] = eye + g[bad, :, None] * g[bad, None, :]
            step = np.linalg.solve(hess, grad[:, :, None])[:, :, 0]
            # Damp long steps: the terms are not quadratic.
            size = np.linalg.norm(step, axis=1, keepdims=True)
            step = step * np.minimum(1.0, 0.1 / np.maximum(size, 1e-300))
            u = u - step
            if np.max(np.abs(step)) < 1e-15:
                break
        return self.lift(u)

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Local chart ``(u, v) -> (x0 + u, y0 + v, f(...))``: exactly on the surface."""
        xy0 = np.asarray(x0, dtype=np.float64).reshape(3)[:2]

        def point(uv: np.ndarray) -> np.ndarray:
            return self.lift(xy0 + np.asarray(uv))[0]

        return point

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        x0, x1, y0, y1 = self.region
        px, py = 0.5 * (x1 - x0), 0.5 * (y1 - y0)
        if not hasattr(self, "_box"):
            gx = np.linspace(x0 - px, x1 + px, 129)
            gy = np.linspace(y0 - py, y1 + py, 129)
            hz = self.height(np.stack(np.meshgrid(gx, gy, indexing="ij"), -1).reshape(-1, 2))
            pad = 0.1 * (float(hz.max() - hz.min()) + px)
            self._box = (np.array([x0 - px, y0 - py, float(hz.min()) - pad]),
                         np.array([x1 + px, y1 + py, float(hz.max()) + pad]))
        lo, hi = self._box
        o, d = _points(origins), _points(directions)
        t0, t1 = _box_interval(o, d, lo, hi)
        t0 = np.maximum(t0, t_min)
        norm = np.linalg.norm(d, axis=1).max(initial=1.0)
        return _march(self.implicit, o, d, t0, t1, step=0.002 * max(px, py) / norm)

    def mesh(self, *, resolution: int = 128) -> trimesh.Trimesh:
        """Grid over ``region`` with ``resolution`` cells along its longer side."""
        x0, x1, y0, y1 = self.region
        step = max(x1 - x0, y1 - y0) / resolution
        nx = max(int(math.ceil((x1 - x0) / step - 1e-9)), 1)
        ny = max(int(math.ceil((y1 - y0) / step - 1e-9)), 1)
        xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
        xy = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
        grid = self.lift(xy.reshape(-1, 2)).reshape(nx + 1, ny + 1, 3)
        return _grid_mesh(grid, self)


# --------------------------------------------------------------------------------------------
# Lights
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DirectionalLight:
    """A light at infinity; ``direction`` is the unit vector toward the light (``L``)."""

    direction: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "direction", _unit3(self.direction, "light.direction"))

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the light."""
        return np.tile(self.direction, (len(_points(x)), 1))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "directional", "direction": self.direction.tolist()}


@dataclass(frozen=True, eq=False)
class PointLight:
    """A point light at ``position``: ``L = normalize(position - x)``."""

    position: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec3(self.position, "light.position"))

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the light."""
        return _normalize(self.position - _points(x))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "point", "position": self.position.tolist()}


@dataclass(frozen=True)
class CameraLight:
    """A flash at each camera centre: ``L = normalize(centre - x)``, so ``N = -r``."""

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the camera ``centre``."""
        if centre is None:
            raise SceneError("light: a camera flash needs the camera centre")
        return _normalize(np.asarray(centre, dtype=np.float64) - _points(x))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "camera"}


LightModel = DirectionalLight | PointLight | CameraLight
"""Any of the three light models of docs/DESIGN.md section 2."""


def as_light(light: LightModel | dict) -> LightModel:
    """A light object from itself or from its scene-file dictionary.

    Raises:
        SceneError: If the dictionary is not a valid light.
    """
    if isinstance(light, DirectionalLight | PointLight | CameraLight):
        return light
    if not isinstance(light, dict):
        raise SceneError(f"light: expected a light or a dict, got {light!r}")
    kind = light.get("type")
    if kind == "directional":
        return DirectionalLight(light.get("direction"))
    if kind == "point":
        return PointLight(light.get("position"))
    if kind == "camera":
        return CameraLight()
    raise SceneError(f"light.type: expected 'directional', 'point' or 'camera', got {kind!r}")


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


def camera_centre(P: np.ndarray) -> np.ndarray:
    """Centre ``c = -M^-1 p4`` of a finite camera ``P = [M | p4]`` (3x4)."""
    P = np.asarray(P, dtype=np.float64)
    return -np.linalg.solve(P[:, :3], P[:, 3])


def pixel_rays(P: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays of pixels: origin at the centre, unit ``normalize(sign(det M) M^-1 q)``.

    Args:
        P: Camera matrix (3x4).
        pixels: Pixels ``(N, 2)``.

    Returns:
        The camera centre ``(3,)`` and the unit directions ``(N, 3)`` into the scene.
    """
    P = np.asarray(P, dtype=np.float64)
    M = P[:, :3]
    q = np.column_stack([np.asarray(pixels, dtype=np.float64).reshape(-1, 2),
                         np.ones(len(np.asarray(pixels).reshape(-1, 2)))])
    d = np.linalg.solve(M, q.T).T * np.sign(np.linalg.det(M))
    return camera_centre(P), _normalize(d)


def project(P: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points.

    Args:
        P: Camera matrix (3x4).
        points: World points ``(N, 3)``.

    Returns:
        Pixels ``(N, 2)`` and depths ``(N,)`` (positive in front of the camera).
    """
    P = np.asarray(P, dtype=np.float64)
    x = _points(points)
    h = x @ P[:, :3].T + P[:, 3]
    M = P[:, :3]
    depth = np.sign(np.linalg.det(M)) * h[:, 2] / np.linalg.norm(M[2])
    return h[:, :2] / h[:, 2:3], depth


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


def reflect(normal: np.ndarray, light_dir: np.ndarray) -> np.ndarray:
    """Mirror direction ``v = 2 (n.L) n - L`` (rows of ``(N, 3)`` or single vectors)."""
    n = np.asarray(normal, dtype=np.float64)
    L = np.asarray(light_dir, dtype=np.float64)
    return 2 * _dot(n, L)[..., None] * n - L


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
        from .scene import Scene

        return Scene.from_dict(copy.deepcopy(self.scene_dict))

    def truth_dict(self) -> dict:
        """The ground truth, JSON-ready."""
        return {
            "name": self.name,
            "truth_points": self.truth_points.tolist(),
            "truth_normals": self.truth_normals.tolist(),
            "light_directions": self.light_directions.tolist(),
            "points": self.points.tolist(),
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


# --------------------------------------------------------------------------------------------
# Built-in scenes
# --------------------------------------------------------------------------------------------


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = math.pi * (3 - math.sqrt(5)) * i
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def octant(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """One eighth of the unit sphere (paper section 4.2).

    Unit sphere at the origin, patch ``x, y, z >= 0``; 24 highlights spread by farthest-point
    sampling over the patch at least 6 degrees from its rim, each seen by its own camera at
    distance 3 under the directional light ``normalize(1, 1, 1)``; point constraints
    ``(1,0,0), (0,1,0), (0,0,1)``; domain ``[-0.1, 1.15]^3``.
    """
    sphere = Sphere((0.0, 0.0, 0.0), 1.0)
    rim = math.sin(math.radians(6.0))
    cand = _fibonacci_sphere(40_000)
    cand = cand[np.all(cand >= rim, axis=1)]
    spec = spread_points(cand, 24, start=np.ones(3) / math.sqrt(3))
    patch = tuple(Halfspace(np.zeros(3), e) for e in np.eye(3))
    return scene_from_points(
        sphere, spec, light=DirectionalLight(np.ones(3)), points=np.eye(3),
        domain=([-0.1] * 3, [1.15] * 3), distance=3.0, patch=patch, name="octant", euler=1,
        mesh_options={"subdivisions": 5}, noise=noise, outliers=outliers, seed=seed,
    )


def car_window(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A gently curved car window (look-alike of the paper's real experiment).

    A patch of a cylinder of radius 2 with a horizontal axis along x, 1.0 wide (x) and 0.6
    high (arc), its centre at the origin with normal tilted 30 degrees toward -y; 38 highlights
    of a directional sun ``normalize(0.3, -0.6, 1)``, each seen by its own camera at distance
    3; two point constraints at diagonal corners; domain: the patch's box grown by 0.15.
    """
    radius = 2.0
    tilt = math.radians(30.0)
    n0 = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    cyl = Cylinder(-radius * n0, (1.0, 0.0, 0.0), radius, reference=n0,
                   extent=(-0.5, 0.5), angles=(-0.15, 0.15))
    half_angle = 0.3 / radius
    # Angles grow from n0 toward axis x n0; bound them with planes through the axis.
    patch = (
        Halfspace((-0.5, 0, 0), (1, 0, 0)),
        Halfspace((0.5, 0, 0), (-1, 0, 0)),
        Halfspace(cyl.point, -np.sin(-half_angle) * cyl.e1 + np.cos(-half_angle) * cyl.e2),
        Halfspace(cyl.point, np.sin(half_angle) * cyl.e1 - np.cos(half_angle) * cyl.e2),
    )
    a, h = np.meshgrid(np.linspace(-0.9, 0.9, 61) * half_angle, np.linspace(-0.45, 0.45, 91))
    spec = spread_points(cyl.at(a.ravel(), h.ravel()), 38, start=cyl.at(0.0, 0.0))
    corners = cyl.at(np.array([-half_angle, half_angle]), np.array([-0.5, 0.5]))
    box = np.concatenate([corners, cyl.at(np.array([-half_angle, half_angle]),
                                          np.array([0.5, -0.5])), cyl.at(0.0, 0.0)[None]])
    domain = (box.min(axis=0) - 0.15, box.max(axis=0) + 0.15)
    return scene_from_points(
        cyl, spec, light=DirectionalLight((0.3, -0.6, 1.0)), points=corners, domain=domain,
        distance=3.0, patch=patch, name="car-window", euler=1, mesh_options={"sections": 64},
        noise=noise, outliers=outliers, seed=seed,
    )


def wine_bottle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A wine bottle lit by the camera flash (look-alike of the paper's real experiment).

    Cylinder of radius 0.04 (metres) with a vertical axis through the origin; the patch of
    glass between the labels spans +-45 degrees around +y and heights 0.11 to 0.19. Eleven
    views along a rising arc at 0.45 from the axis (azimuth -35 to +35 degrees, height 0.12 to
    0.18), each looking at ``(0, 0, 0.15)``; the highlight is searched where the flash mirrors
    back into each camera. Four point constraints at the label corners (+-40 degrees, heights
    0.115 and 0.185); domain: the patch's box grown by 0.01.
    """
    radius = 0.04
    cyl = Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), radius, reference=(0.0, 1.0, 0.0),
                   extent=(0.11, 0.19), angles=(-math.pi / 4, math.pi / 4))
    half = math.pi / 4
    patch = (
        Halfspace((0, 0, 0.11), (0, 0, 1)),
        Halfspace((0, 0, 0.19), (0, 0, -1)),
        Halfspace(cyl.point, -np.sin(-half) * cyl.e1 + np.cos(-half) * cyl.e2),
        Halfspace(cyl.point, np.sin(half) * cyl.e1 - np.cos(half) * cyl.e2),
    )
    views = 11
    az = np.radians(np.linspace(-35.0, 35.0, views))
    height = np.linspace(0.12, 0.18, views)
    dist = 0.45
    centres = cyl.point + (dist * (np.cos(az)[:, None] * cyl.e1 + np.sin(az)[:, None] * cyl.e2)
                           + height[:, None] * cyl.axis)
    label = math.radians(40.0)
    pts = cyl.at(np.array([-label, label, label, -label]), np.array([0.115, 0.115, 0.185, 0.185]))
    box = cyl.mesh(sections=32).vertices
    domain = (box.min(axis=0) - 0.01, box.max(axis=0) + 0.01)
    return scene_from_path(
        cyl, centres, light=CameraLight(), look_at_points=(0.0, 0.0, 0.15), points=pts,
        domain=domain, patch=patch, name="wine-bottle", euler=1, mesh_options={"sections": 96},
        noise=noise, outliers=outliers, seed=seed,
    )


def ellipsoid_cap(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                  ) -> SyntheticScene:
    """The top cap of an ellipsoid under a point light.

    Ellipsoid at the origin with radii ``(1, 0.7, 0.5)``, cap ``z >= 0.25``; point light at
    ``(0.6, -0.4, 3)``; 20 highlights spread over ``z >= 0.3``, cameras at distance 2.5; four
    point constraints on the rim of the cap (``z = 0.25``); domain
    ``[-0.95, 0.95] x [-0.7, 0.7] x [0.1, 0.62]``.
    """
    ell = Ellipsoid((0.0, 0.0, 0.0), (1.0, 0.7, 0.5))
    verts = np.asarray(ell.mesh(subdivisions=6).vertices)
    spec = spread_points(verts[verts[:, 2] >= 0.3], 20, start=(0.0, 0.0, 0.5))
    rim = math.sqrt(1 - (0.25 / 0.5) ** 2)
    pts = np.array([[rim, 0, 0.25], [0, 0.7 * rim, 0.25], [-rim, 0, 0.25], [0, -0.7 * rim, 0.25]])
    return scene_from_points(
        ell, spec, light=PointLight((0.6, -0.4, 3.0)), points=pts,
        domain=([-0.95, -0.7, 0.1], [0.95, 0.7, 0.62]), distance=2.5,
        patch=(Halfspace((0, 0, 0.25), (0, 0, 1)),), name="ellipsoid-cap", euler=1,
        mesh_options={"subdivisions": 5}, noise=noise, outliers=outliers, seed=seed,
    )


def paraboloid(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A dome ``z = 0.3 - 0.6 x^2 - 0.4 y^2`` over ``[-0.5, 0.5]^2``.

    Directional light ``normalize(0.2, -0.1, 1)``; 25 highlights spread over
    ``[-0.45, 0.45]^2``, cameras at distance 2.5; the four region corners as point constraints;
    domain ``[-0.6, 0.6]^2 x [-0.2, 0.45]``.
    """
    surf = Paraboloid((0.0, 0.0, 0.3), -0.6, -0.4, region=(-0.5, 0.5, -0.5, 0.5))
    g = np.linspace(-0.45, 0.45, 61)
    xy = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    spec = spread_points(surf.lift(xy), 25, start=(0.0, 0.0, 0.3))
    return scene_from_points(
        surf, spec, light=DirectionalLight((0.2, -0.1, 1.0)), points=surf.corners(),
        domain=([-0.6, -0.6, -0.2], [0.6, 0.6, 0.45]), distance=2.5, name="paraboloid", euler=1,
        mesh_options={"resolution": 96}, noise=noise, outliers=outliers, seed=seed,
    )


def saddle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A saddle ``z = 0.4 (x^2 - y^2)`` over ``[-0.5, 0.5]^2``.

    Directional light ``normalize(-0.2, 0.3, 1)``; 30 highlights spread over
    ``[-0.45, 0.45]^2``, cameras at distance 2.5; point constraints at the four region corners
    and the saddle point; domain ``[-0.6, 0.6]^2 x [-0.25, 0.25]``.
    """
    surf = Saddle((0.0, 0.0, 0.0), 0.4, region=(-0.5, 0.5, -0.5, 0.5))
    g = np.linspace(-0.45, 0.45, 61)
    xy = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    spec = spread_points(surf.lift(xy), 30, start=(0.0, 0.0, 0.0))
    pts = np.concatenate([surf.corners(), [[0.0, 0.0, 0.0]]])
    return scene_from_points(
        surf, spec, light=DirectionalLight((-0.2, 0.3, 1.0)), points=pts,
        domain=([-0.6, -0.6, -0.25], [0.6, 0.6, 0.25]), distance=2.5, name="saddle", euler=1,
        mesh_options={"resolution": 96}, noise=noise, outliers=outliers, seed=seed,
    )


# --------------------------------------------------------------------------------------------
# Scenes of every shape class, their geometry varied by the seed
# --------------------------------------------------------------------------------------------

FREEFORM_HIGHLIGHTS = 60
"""Default number of highlights of the ``freeform`` scene."""

DOMAIN_MARGIN = 0.12
"""Margin of the domain around a closed object, as a fraction of its largest extent."""


def _shape_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of a scene's geometry: its own stream, apart from the noise's."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _around(count: int, rng: np.random.Generator, *, jitter: float = 0.25) -> np.ndarray:
    """``count`` unit directions all around (both hemispheres), rotated and jittered."""
    d = _fibonacci_sphere(count) @ _random_rotation(rng).T
    d += jitter / math.sqrt(count) * rng.standard_normal(d.shape)
    return _normalize(d)


def _margin_box(vertices: np.ndarray, margin: float = DOMAIN_MARGIN
                ) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    pad = margin * float(np.max(hi - lo))
    return lo - pad, hi + pad


def _pick_points(candidates: np.ndarray, surface: Surface, count: int,
                 rng: np.random.Generator) -> np.ndarray:
    """``count`` spread surface points among ``candidates``, which ones chosen by ``rng``."""
    cand = _points(candidates)
    cand = cand[rng.choice(len(cand), size=min(len(cand), 400), replace=False)]
    start = cand[int(rng.integers(len(cand)))]
    return surface.closest_point(spread_points(cand, count, start=start))


def _seen(surface: Surface, x: np.ndarray, light: LightModel, distance: float,
          *, min_cos: float = 0.05) -> np.ndarray:
    """Whether a camera placed by :func:`place_camera` at ``distance`` sees each point ``x``."""
    n = surface.normal(x)
    if isinstance(light, CameraLight):
        v, ok = n, np.ones(len(x), dtype=bool)
    else:
        L = light.towards(x)
        ok = _dot(n, L) >= min_cos
        v = _normalize(reflect(n, L))
    c = x + distance * v
    ok &= surface.implicit(c) > 0
    d = x - c
    t = surface.intersect(c, d / distance, t_min=1e-9 * distance)
    return ok & np.isfinite(t) & (np.abs(t - distance) <= 1e-7 * distance)


def _points_scene(surface: Surface, candidates: np.ndarray, count: int, *, light: LightModel,
                  distance: float, rng: np.random.Generator, **options: Any) -> SyntheticScene:
    """:func:`scene_from_points` with ``count`` well-spread candidates that can be seen."""
    order = spread_points(candidates, min(len(candidates), 2 * count + 20),
                          start=candidates[int(rng.integers(len(candidates)))])
    good = order[_seen(surface, surface.closest_point(order), light, distance)]
    if len(good) < count:
        raise SceneError(f"highlights: only {len(good)} of the {count} asked can be seen")
    return scene_from_points(surface, good[:count], light=light, distance=distance,
                             layout_seed=int(rng.integers(2**31)), **options)


def sphere_around(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                  ) -> SyntheticScene:
    """A whole sphere seen all around by 28 flash cameras (one highlight each), 6 points.

    Radius 0.9-1.1 and centre within 0.1 of the origin (by seed); cameras on jittered
    directions covering both hemispheres at 3-3.4 radii from the centre; domain: the sphere's
    box grown by 12% of its diameter on each side. Outliers are false highlights on the
    sphere.
    """
    rng = _shape_rng(seed, "sphere-around")
    radius = float(rng.uniform(0.9, 1.1))
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Sphere(centre, radius)
    mesh = surf.mesh(subdivisions=5)
    centres = centre + radius * rng.uniform(3.0, 3.4) * _around(28, rng)
    return scene_from_path(
        surf, centres, light=CameraLight(), look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 6, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, name="sphere-around", mesh_options={"subdivisions": 5},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface", closed=True,
        euler=2,
    )


def ellipsoid_around(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                     ) -> SyntheticScene:
    """A whole ellipsoid (axes about 1, 0.82, 0.67) seen all around, one lamp per camera.

    28 cameras on jittered directions all around at 3.2 from the centre; each carries its own
    directional light, 25-40 degrees off its viewing direction, and sees one highlight. Six
    points; domain: the box grown by 12% of the longest axis. The seed varies the radii (by
    up to 6%), the centre, the cameras and the lights.
    """
    rng = _shape_rng(seed, "ellipsoid-around")
    radii = np.array([1.0, 0.82, 0.67]) * rng.uniform(0.94, 1.06, 3)
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Ellipsoid(centre, radii)
    mesh = surf.mesh(subdivisions=5)
    dirs = _around(28, rng)
    lights = []
    for d in dirs:
        t1, t2 = _tangent_basis(d)
        a = rng.uniform(0, 2 * math.pi)
        tilt = math.radians(rng.uniform(25.0, 40.0))
        lights.append(DirectionalLight(math.cos(tilt) * d + math.sin(tilt)
                                       * (math.cos(a) * t1 + math.sin(a) * t2)))
    return scene_from_path(
        surf, centre + 3.2 * dirs, light=lights, look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 6, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, name="ellipsoid-around", mesh_options={"subdivisions": 5},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface", closed=True,
        euler=2,
    )


def torus(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A ring torus (tube about 0.35 of the major radius) seen all around by flash cameras.

    Major radius 0.95-1.05, tube 0.33-0.37 of it, axis tilted up to about 10 degrees from
    ``z`` (by seed). 30 cameras on jittered directions all around at 4 from the centre plus
    one above and one below looking through the hole; each keeps up to 3 visible highlights
    (a torus shows several). Eight points; domain: the box grown by 12% of the diameter.
    """
    rng = _shape_rng(seed, "torus")
    major = float(rng.uniform(0.95, 1.05))
    minor = major * float(rng.uniform(0.33, 0.37))
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.1 * rng.standard_normal(3))
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Torus(centre, axis, major, minor)
    mesh = surf.mesh()
    dirs = _around(30, rng)
    t1, _ = _tangent_basis(axis)
    poles = [_normalize(s * axis + 0.12 * t1 + 0.05 * rng.standard_normal(3)) for s in (1, -1)]
    dirs = np.concatenate([dirs, poles])
    return scene_from_path(
        surf, centre + 4.0 * dirs, light=CameraLight(), look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 8, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, intrinsics=Intrinsics(focal=560.0), up=axis,
        name="torus", noise=noise, outliers=outliers, seed=seed, per_view=3,
        false_highlights="surface", closed=True, euler=0,
    )


def bottle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A bottle (body, shoulder, neck; a surface of revolution) seen by two rings of flashes.

    Body radius about 0.35, neck about 0.13, shoulder about 0.35 above the base point, axis
    near ``z`` (all varied by seed). 14 cameras on a ring at the body's height and 14 above the
    shoulder, 1.6 from the axis; each keeps up to 2 highlights. Six points. The domain holds
    the bottle's width with a 12% margin and cuts its body below (height -0.45) and its neck
    above (height 0.85), so the truth is an open tube (Euler number 0).
    """
    rng = _shape_rng(seed, "bottle")
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.05 * rng.standard_normal(3))
    base = rng.uniform(-0.05, 0.05, 3)
    body = 0.35 * float(rng.uniform(0.93, 1.07))
    surf = Revolution(base, axis, body=body, neck=0.13 * float(rng.uniform(0.9, 1.1)),
                      shoulder=0.35 + float(rng.uniform(-0.04, 0.04)),
                      width=0.09 * float(rng.uniform(0.9, 1.1)))
    # The domain: heights -0.45..0.85 along z, the width with a margin (the axis leans a bit,
    # so the cut is taken along z through the tube's ends).
    lo_z, hi_z = base[2] - 0.45, base[2] + 0.85
    pad = DOMAIN_MARGIN * 2 * body
    h_lo = (lo_z - base[2]) / axis[2] - 0.2
    h_hi = (hi_z - base[2]) / axis[2] + 0.2
    full = surf.mesh(extent=(h_lo, h_hi))
    patch = (Halfspace((0, 0, lo_z), (0, 0, 1)), Halfspace((0, 0, hi_z), (0, 0, -1)))
    verts = clip_mesh(full, patch).vertices
    lo = np.append(verts.min(axis=0)[:2] - pad, lo_z)
    hi = np.append(verts.max(axis=0)[:2] + pad, hi_z)
    centres, targets = [], []
    for height, aim in ((0.0, 0.0), (1.05, 0.45)):
        az = np.linspace(0, 2 * math.pi, 14, endpoint=False) + rng.uniform(0, 2 * math.pi)
        az = az + rng.uniform(-0.1, 0.1, len(az))
        ring = 1.6 * (np.cos(az)[:, None] * surf.e1 + np.sin(az)[:, None] * surf.e2)
        centres.append(base + ring + (height + rng.uniform(-0.05, 0.05, (len(az), 1))) * axis)
        targets.append(np.tile(base + aim * axis, (len(az), 1)))
    return scene_from_path(
        surf, np.concatenate(centres), light=CameraLight(),
        look_at_points=np.concatenate(targets),
        points=_pick_points(verts[(verts[:, 2] > lo_z + 0.05) & (verts[:, 2] < hi_z - 0.05)],
                            surf, 6, rng), domain=(lo, hi),
        candidates=verts, patch=patch, up=axis, name="bottle",
        mesh_options={"extent": (h_lo, h_hi)}, noise=noise, outliers=outliers, seed=seed,
        per_view=2, false_highlights="surface", closed=False, euler=0,
    )


def wrap(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A cylinder patch wrapping 200-240 degrees around its axis, seen from its convex side.

    Radius about 0.5, axial length about 0.8, axis near ``z`` (by seed); 36 highlights spread
    over the patch (inset from its edges), each seen by its own flash camera 2 from the point
    along the normal: a ring of cameras around the axis. Five points; domain: the patch's box
    grown by 12% of its size. An open patch (Euler number 1).
    """
    rng = _shape_rng(seed, "wrap")
    radius = 0.5 * float(rng.uniform(0.93, 1.07))
    span = math.radians(float(rng.uniform(200.0, 240.0)))
    start = float(rng.uniform(0, 2 * math.pi))
    half = 0.4 * float(rng.uniform(0.9, 1.1))
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.08 * rng.standard_normal(3))
    cyl = Cylinder(rng.uniform(-0.05, 0.05, 3), axis, radius, extent=(-half, half),
                   angles=(start, start + span))
    a, h = np.meshgrid(start + span * np.linspace(0.05, 0.95, 61),
                       np.linspace(-0.85, 0.85, 31) * half)
    cand = cyl.at(a.ravel(), h.ravel())
    mesh = cyl.mesh(sections=128)
    corners = cyl.at(start + span * np.array([0.02, 0.98, 0.98, 0.02, 0.5]),
                     half * np.array([-0.95, -0.95, 0.95, 0.95, 0.0]))
    return _points_scene(
        cyl, cand, 36, light=CameraLight(), distance=2.0, rng=rng, points=corners,
        domain=_margin_box(mesh.vertices), up=axis, name="wrap",
        mesh_options={"sections": 128}, noise=noise, outliers=outliers, seed=seed,
        false_highlights="surface", closed=False, euler=1,
    )


def _freeform_surface(rng: np.random.Generator) -> FreeformHeightField:
    waves = []
    for _ in range(3):
        k = 2 * math.pi * float(rng.uniform(0.7, 1.4))
        ang = float(rng.uniform(0, math.pi))
        waves.append((float(rng.uniform(0.03, 0.05)), k * math.cos(ang), k * math.sin(ang),
                      float(rng.uniform(0, 2 * math.pi))))
    bump = (float(rng.uniform(0.1, 0.14)), *rng.uniform(-0.2, 0.2, 2),
            float(rng.uniform(0.11, 0.15)))
    return FreeformHeightField(waves=waves, bumps=[bump], region=(-0.5, 0.5, -0.5, 0.5))


def freeform(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
             highlights: int = FREEFORM_HIGHLIGHTS) -> SyntheticScene:
    """A free-form height-field patch (three sine waves and a Gaussian bump), seen from above.

    Over ``[-0.5, 0.5]^2``: waves of amplitude 0.03-0.05 and wavelength 0.7-1.4, a bump of
    height 0.10-0.14 (all by seed); ``highlights`` (default 60) highlights spread over the
    patch, each seen by its own camera 2.5 away under a directional light near ``+z``. Five
    points (four near the corners, one inside); domain: the patch grown by 0.12 each side.

    Raises:
        SceneError: If ``highlights`` is not an integer from 4 to 400.
    """
    if isinstance(highlights, bool) or not isinstance(highlights, int | np.integer) or not (
            4 <= highlights <= 400):
        raise SceneError(f"highlights: must be an integer from 4 to 400, got {highlights!r}")
    rng = _shape_rng(seed, "freeform")
    surf = _freeform_surface(rng)
    light = DirectionalLight(np.array([0.0, 0.0, 1.0]) + 0.25 * rng.standard_normal(3) * [1, 1, 0])
    g = np.linspace(-0.46, 0.46, 93)
    cand = surf.lift(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))
    corners = np.array([[-0.44, -0.44], [0.44, -0.44], [0.44, 0.44], [-0.44, 0.44]])
    corners = corners + rng.uniform(-0.03, 0.03, corners.shape)
    pts = surf.lift(np.concatenate([corners, rng.uniform(-0.25, 0.25, (1, 2))]))
    return _points_scene(
        surf, cand, int(highlights), light=light, distance=2.5, rng=rng, points=pts,
        domain=_sheet_domain(surf), name="freeform", mesh_options={"resolution": 128},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface",
        closed=False, euler=1,
    )


def _sheet_domain(surf: FreeformHeightField, margin: float = DOMAIN_MARGIN
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A box that the sheet cuts through: the region grown by ``margin``, heights padded."""
    x0, x1, y0, y1 = surf.region
    g = np.stack(np.meshgrid(np.linspace(x0 - margin, x1 + margin, 97),
                             np.linspace(y0 - margin, y1 + margin, 97), indexing="ij"), -1)
    hz = surf.height(g.reshape(-1, 2))
    return (np.array([x0 - margin, y0 - margin, hz.min() - margin]),
            np.array([x1 + margin, y1 + margin, hz.max() + margin]))


def point_light(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A bumpy dome lit by a point lamp 2 above it: 30 highlights, 5 points.

    Dome ``0.3 - 0.5 x^2 - 0.4 y^2`` (coefficients varied by up to 15%) with two Gaussian bumps
    of height 0.04-0.06 over ``[-0.5, 0.5]^2``; the lamp within 0.3 of the axis at height 2;
    each highlight seen by its own camera 2.5 away. Domain: the patch grown by 0.12.
    """
    rng = _shape_rng(seed, "point-light")
    bumps = [(float(rng.uniform(0.04, 0.06)), *rng.uniform(-0.3, 0.3, 2),
              float(rng.uniform(0.09, 0.13))) for _ in range(2)]
    surf = FreeformHeightField(z0=0.3, dome=np.array([0.5, 0.4]) * rng.uniform(0.85, 1.15, 2),
                               bumps=bumps, region=(-0.5, 0.5, -0.5, 0.5))
    lamp = PointLight(np.append(rng.uniform(-0.3, 0.3, 2), 2.0))
    g = np.linspace(-0.46, 0.46, 71)
    cand = surf.lift(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))
    pts = surf.lift(np.array([[-0.45, -0.45], [0.45, -0.45], [0.45, 0.45], [-0.45, 0.45],
                              [0.0, 0.0]]) + rng.uniform(-0.03, 0.03, (5, 2)))
    return _points_scene(
        surf, cand, 30, light=lamp, distance=2.5, rng=rng, points=pts,
        domain=_sheet_domain(surf), name="point-light", mesh_options={"resolution": 128},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface",
        closed=False, euler=1,
    )


SCENES: dict[str, Callable[..., SyntheticScene]] = {
    "octant": octant,
    "car-window": car_window,
    "wine-bottle": wine_bottle,
    "ellipsoid-cap": ellipsoid_cap,
    "paraboloid": paraboloid,
    "saddle": saddle,
    "sphere-around": sphere_around,
    "ellipsoid-around": ellipsoid_around,
    "torus": torus,
    "bottle": bottle,
    "wrap": wrap,
    "freeform": freeform,
    "point-light": point_light,
}


def scene_names() -> list[str]:
    """Names of the built-in scenes."""
    return list(SCENES)


def make_scene(name: str, *, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
               **options: Any) -> SyntheticScene:
    """A built-in scene by name (see :data:`SCENES`).

    Args:
        name: One of :func:`scene_names`.
        noise: Pixel noise standard deviation in pixels.
        outliers: Fraction of specularities replaced by false ones.
        seed: Seed of the noise and outliers; for the scenes of every shape class
            (``sphere-around`` to ``point-light``) also of the geometry (sizes, bumps, camera
            jitter, which points are chosen). The paper's scenes keep a fixed geometry.
        **options: Options only some scenes take (``freeform``: ``highlights``).

    Raises:
        SceneError: If the name is unknown, a scene does not take an option, or the settings
            are out of range.
    """
    if name not in SCENES:
        raise SceneError(f"scene: unknown name {name!r}, expected one of {scene_names()}")
    make = SCENES[name]
    params = inspect.signature(make).parameters
    for key in options:
        if key not in params:
            raise SceneError(f"{key}: scene {name!r} takes no such option")
    return make(noise=noise, outliers=outliers, seed=seed, **options)
