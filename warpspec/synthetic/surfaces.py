"""Surfaces with ground truth: the protocol and its shapes (sphere to freeform)."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import trimesh

from ..errors import SceneError
from ..evaluate import FEATURE_AB, FEATURE_AC, FEATURE_BC, FEATURE_FACE, closest_point
from ..geometry import (
    _dot,
    _normalize,
    _points,
    _unit3,
    _vec3,
)


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


def _grid_mesh(grid: np.ndarray, surface: Surface, *, wrap: bool = False) -> trimesh.Trimesh:
    """Triangulate an ``(nu, nv, 3)`` grid of surface points, facing along ``surface.normal``.

    With ``wrap`` the last row joins the first (a seam closed around an axis).
    """
    nu, nv = grid.shape[:2]
    idx = np.arange(nu * nv).reshape(nu, nv)
    nxt = np.roll(idx, -1, axis=0)
    if not wrap:
        idx, nxt = idx[:-1], nxt[:-1]
    a, b = idx[:, :-1].ravel(), nxt[:, :-1].ravel()
    c, d = nxt[:, 1:].ravel(), idx[:, 1:].ravel()
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


class Blob(Surface):
    """A closed star-shaped blob: a sphere raised by smooth bumps.

    The surface is ``|x - centre| = radius * (1 + sum_k a_k exp((u . d_k - 1) / w_k^2))`` with
    ``u`` the unit direction from ``centre`` to ``x``: each bump ``(a_k, d_k, w_k)`` raises the
    sphere by ``a_k`` radii around the direction ``d_k``, over an angle of about ``w_k``
    radians. No quadric, torus or surface of revolution fits it: a closed free-form object.

    Args:
        centre: Centre ``(3,)``.
        radius: Radius of the sphere under the bumps (> 0).
        bumps: ``(height, direction, width)`` of each bump: height as a share of the radius
            (>= 0), direction ``(3,)`` (any length), width in radians (> 0).
    """

    closed = True

    def __init__(self, centre: Sequence[float], radius: float,
                 bumps: Sequence[tuple[float, Sequence[float], float]]) -> None:
        self.centre = _vec3(centre, "centre")
        if not (np.isfinite(radius) and radius > 0):
            raise SceneError(f"radius: must be a positive number, got {radius!r}")
        self.radius = float(radius)
        self.bumps = []
        for k, (height, direction, width) in enumerate(bumps):
            if not (np.isfinite(height) and height >= 0 and np.isfinite(width) and width > 0):
                raise SceneError(f"bumps[{k}]: need height >= 0 and width > 0, got "
                                 f"{height!r}, {width!r}")
            self.bumps.append((float(height), _unit3(direction, f"bumps[{k}] direction"),
                               float(width)))
        self.largest = self.radius * (1.0 + sum(b[0] for b in self.bumps))
        """Radius of a ball about ``centre`` that holds the blob."""

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = _points(x) - self.centre
        rho = np.linalg.norm(y, axis=1)
        u = np.where(rho[:, None] > 0, y / np.where(rho > 0, rho, 1.0)[:, None], [0.0, 0.0, 1.0])
        return rho, u

    def height(self, u: np.ndarray) -> np.ndarray:
        """The surface's distance from the centre along unit directions ``u`` ``(N, 3)``."""
        out = np.ones(len(u))
        for a, d, w in self.bumps:
            out += a * np.exp((u @ d - 1.0) / w**2)
        return self.radius * out

    def _height_gradient(self, u: np.ndarray) -> np.ndarray:
        """Gradient of :meth:`height`'s formula in ``u`` (not yet projected on the sphere)."""
        g = np.zeros_like(u)
        for a, d, w in self.bumps:
            g += (a * np.exp((u @ d - 1.0) / w**2) / w**2)[:, None] * d
        return self.radius * g

    def at(self, u: np.ndarray) -> np.ndarray:
        """Surface points along unit directions ``u`` from the centre ``(N, 3)``."""
        u = _points(u)
        return self.centre + self.height(u)[:, None] * u

    def implicit(self, x: np.ndarray) -> np.ndarray:
        """``|x - centre| - height(u)``: the sign of the distance, not the distance itself."""
        rho, u = self._split(x)
        return rho - self.height(u)

    def _gradient(self, x: np.ndarray) -> np.ndarray:
        rho, u = self._split(x)
        g = self._height_gradient(u)
        tangent = g - _dot(g, u)[:, None] * u
        return u - tangent / np.maximum(rho, 1e-300)[:, None]

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit gradient of :meth:`implicit`: the surface normal at surface points."""
        return _normalize(self._gradient(x))

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest points: the radial projection, then steps along the surface.

        Each step moves along the tangent part of ``x - p`` and back onto the surface along
        the radius, until ``x - p`` is normal to it.
        """
        x = _points(x)
        _, u = self._split(x)
        p = self.at(u)
        for _ in range(500):
            n = self.normal(p)
            d = x - p
            tangent = d - _dot(d, n)[:, None] * n
            # a far point's tangent offset is larger than the arc to walk by about the ratio
            # of its distance from the centre to the surface's (exactly so on a sphere)
            rho = np.linalg.norm(p - self.centre, axis=1)
            step = rho / (rho + np.linalg.norm(d, axis=1))
            p = self.at(self._split(p + step[:, None] * tangent)[1])
            if float(np.max(np.linalg.norm(tangent, axis=1), initial=0.0)) < 1e-13 * self.largest:
                break
        return p

    def chart(self, x0: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """Chart by direction around ``x0``: smooth and exactly on the surface."""
        _, u0 = self._split(np.asarray(x0, dtype=np.float64).reshape(1, 3))
        t1, t2 = _tangent_basis(u0[0])

        def point(uv: np.ndarray) -> np.ndarray:
            return self.at(_normalize((u0[0] + uv[0] * t1 + uv[1] * t2)[None]))[0]

        return point

    def intersect(  # noqa: D102
        self, origins: np.ndarray, directions: np.ndarray, *, t_min: float = 1e-9
    ) -> np.ndarray:
        o, d = _points(origins), _points(directions)
        # only the ball of radius ``largest`` can hold a crossing
        oc = o - self.centre
        t0, t1 = _quadratic_span(_dot(d, d), 2 * _dot(d, oc),
                                 _dot(oc, oc) - (self.largest * (1 + 1e-6)) ** 2)
        norm = np.linalg.norm(d, axis=1).max(initial=1.0)
        return _march(self.implicit, o, d, np.maximum(t0, t_min), t1,
                      step=0.002 * self.radius / norm)

    def mesh(self, *, subdivisions: int = 5) -> trimesh.Trimesh:
        """The icosphere of ``subdivisions`` levels (5: 20480 triangles) moved onto the blob."""
        m = trimesh.creation.icosphere(subdivisions=subdivisions)
        return trimesh.Trimesh(vertices=self.at(np.asarray(m.vertices)), faces=m.faces,
                               process=False)


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
        return _grid_mesh(grid, self, wrap=True)  # the seam closed around the axis


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


class _HeightField(Surface):
    """A surface ``z = height(x, y)`` over ``region``, facing ``+z``.

    Subclasses give ``_terms`` (height, gradient and Hessian at plane points) and ``region``;
    the closest point takes ``_NEWTON_STEPS`` Newton steps, each at most ``_NEWTON_DAMP`` long
    when that is set.
    """

    region: tuple[float, float, float, float]
    _NEWTON_STEPS = 60
    _NEWTON_DAMP: float | None = None

    @abstractmethod
    def _terms(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height ``(N,)``, gradient ``(N, 2)`` and Hessian at plane points ``(N, 2)``."""

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
        """Closest points by Newton iterations on the height-field parameters.

        Gauss-Newton where the Hessian is not positive definite. Exact for points within the
        surface's smallest radius of curvature (where the closest point is unique), which
        covers every use here.
        """
        x = _points(x)
        u = x[:, :2].copy()
        eye = np.eye(2)
        for _ in range(self._NEWTON_STEPS):
            f, g, H = self._terms(u)
            res = f - x[:, 2]
            grad = (u - x[:, :2]) + res[:, None] * g
            hess = eye + g[:, :, None] * g[:, None, :] + res[:, None, None] * H
            det = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] * hess[:, 1, 0]
            bad = (det <= 1e-12) | (hess[:, 0, 0] <= 0)
            hess[bad] = eye + g[bad, :, None] * g[bad, None, :]
            step = np.linalg.solve(hess, grad[:, :, None])[:, :, 0]
            if self._NEWTON_DAMP is not None:
                size = np.linalg.norm(step, axis=1, keepdims=True)
                step = step * np.minimum(1.0, self._NEWTON_DAMP / np.maximum(size, 1e-300))
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


class QuadraticHeightField(_HeightField):
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

    def _terms(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.height(xy), self.gradient(xy), self.hessian

    def gradient(self, xy: np.ndarray) -> np.ndarray:
        """Gradient ``(N, 2)`` of the height at plane points ``(N, 2)``."""
        w = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - self.origin
        return self.slope + w @ self.hessian

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
    with np.errstate(over="ignore", invalid="ignore"):
        span = t1 - t0
    # an unbounded span (or one past the largest float) is not searched
    todo = np.flatnonzero(np.isfinite(span) & (span > 0))
    if len(todo) == 0:
        return out
    span = float(np.max(span[todo]))
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


def _quadratic_span(a: np.ndarray, b: np.ndarray, c: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameters ``(t0, t1)`` where ``a t^2 + b t + c <= 0`` (``a >= 0``; empty: t0 > t1).

    The inside of a ball or an infinite cylinder along rays. Where ``a == 0`` (a ray along
    the cylinder's axis, ``b == 0`` too) it is every ``t`` when ``c <= 0`` (``(-inf, inf)``,
    which :func:`_march` does not search: bound it first) and none otherwise.
    """
    disc = b * b - 4 * a * c
    meets = (a > 0) & (disc >= 0)
    along = (a == 0) & (c <= 0)
    root = np.sqrt(np.where(meets, disc, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        t0 = np.where(meets, (-b - root) / (2 * a), np.where(along, -np.inf, np.inf))
        t1 = np.where(meets, (-b + root) / (2 * a), np.where(along, np.inf, -np.inf))
    return t0, t1


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


SHOULDER_WIDTHS = 40.0
"""Half-height, in shoulder widths, of the band where a :class:`Revolution`'s radius changes."""


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
        a = _dot(dc, dc)
        # a ray within 1e-12 rad of the axis keeps its distance from it: its span inside the
        # cylinder is unbounded or ~1e16 long, and it can cross only where the radius changes
        along = a <= 1e-24 * _dot(d, d)
        t0, t1 = _quadratic_span(np.where(along, 0.0, a), np.where(along, 0.0, 2 * _dot(dc, oc)),
                                 _dot(oc, oc) - hull.radius**2)
        if along.any():
            # beyond SHOULDER_WIDTHS widths of the shoulder the radius is body or neck to
            # the last bit (1 - tanh(40) is 4e-35)
            with np.errstate(divide="ignore", invalid="ignore"):
                ta, tb = ((self.shoulder + k * SHOULDER_WIDTHS * self.width
                           - (o - self.base) @ self.axis) / (d @ self.axis) for k in (-1, 1))
            t0 = np.where(along, np.maximum(t0, np.minimum(ta, tb)), t0)
            t1 = np.where(along, np.minimum(t1, np.maximum(ta, tb)), t1)
        norm = np.linalg.norm(d, axis=1).max(initial=1.0)
        return _march(self.implicit, o, d, np.maximum(t0, t_min), t1,
                      step=0.01 * self.neck / norm)

    def mesh(self, *, sections: int = 128, extent: tuple[float, float] | None = None
             ) -> trimesh.Trimesh:
        """Open tube over ``extent``: ``sections`` around, rings about as fine along the axis."""
        lo, hi = extent or self.extent
        step = math.pi * (self.body + self.neck) / sections
        rings = min(max(int(math.ceil((hi - lo) / step)), 1), 4 * sections)
        ang = np.linspace(0, 2 * math.pi, sections, endpoint=False)
        hgt = np.linspace(lo, hi, rings + 1)
        grid = self.at(ang[:, None], hgt[None, :])
        return _grid_mesh(grid, self, wrap=True)


class FreeformHeightField(_HeightField):
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
    _NEWTON_STEPS = 100
    _NEWTON_DAMP = 0.1  # the terms are not quadratic: long steps are cut to this

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
