"""A torus fitted to the normal lines of highlights: the genus-one candidate of the start.

Every normal line of a surface of revolution meets its axis, and every normal line of a torus
passes through its core circle (radius ``R`` about the axis, in the plane through the centre).
With a flash at the camera the normal at a highlight points back along its ray, so the ray is a
normal line; under another light the implicit start passes the normal line through the ray's
current hit, fitting and intersecting in turn. The fit (docs/DESIGN.md section 7):

1. the axis: the direction, among 2,000 spread over a hemisphere, and the point whose line the
   normal lines pass nearest (median distance), the point solved by least squares for each
   direction;
2. the core circle: in each line's meridian plane (through the axis), the point ``(R, z0)`` of
   the plane's (distance from the axis, height) coordinates that the lines pass nearest;
3. the tube radius ``r``: the median distance of the points from the core circle;
4. all seven numbers refined together by robust least squares (scipy's ``soft_l1`` loss) on
   the lines' distances from the core circle and the points' distances from the torus.

:func:`points_torus` is a ring through the points alone: under another light the rounds of
fitting and intersecting may start from the rays' hits on it.

:func:`refit_torus` refits a torus with the points weighed as noisy: each ray should pass
through the torus point whose normal is the one it asks (:func:`pixel_misses`, in pixels), and
under a lamp the rays, not the points, fix the tube's radius (:mod:`warpspec.pixel_fit`).

The implicit start takes the torus when the quadric does not meet the normals and the torus
does, as it would take a quadric (the same shares of rays met within noise and missed by
3-10 degrees, the points held as closely).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .geometry import best_fit_plane
from .normal_lines import best_axis, first_crossing
from .pixel_fit import NOISY_POINT_VOXELS, as_arrays, ray_misses, refine

__all__ = ["Torus", "first_hits", "fit_torus", "pixel_misses", "points_torus", "refit_torus"]

MIN_RAYS = 12
"""Fewest normal lines a torus is fitted to."""
RING = 1.2
"""The fitted torus must be a ring: ``R >= RING * r`` (else it is no candidate)."""


@dataclass(frozen=True)
class Torus:
    """A torus: centre, unit axis, core radius ``R`` and tube radius ``r`` (world units).

    A ring (:attr:`is_ring`) is a candidate start; a fit that is none (a spindle) may still
    be a first guess for the rounds of fitting and intersecting.
    """

    centre: np.ndarray
    axis: np.ndarray
    R: float
    r: float

    @property
    def is_ring(self) -> bool:
        """Whether the tube leaves a hole (``R >= RING r``): only a ring is a start."""
        return self.R >= RING * self.r

    def _meridian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v = np.asarray(x, dtype=np.float64) - self.centre
        z = v @ self.axis
        radial = v - z[:, None] * self.axis
        return np.linalg.norm(radial, axis=1), z, radial

    def value(self, x: np.ndarray) -> np.ndarray:
        """Signed distance (negative inside the tube) at points ``(N, 3)``."""
        rho, z, _ = self._meridian(x)
        return np.hypot(rho - self.R, z) - self.r

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal of the nearest tube point, ``(N, 3)``."""
        rho, z, radial = self._meridian(x)
        e = radial / np.maximum(rho, 1e-300)[:, None]
        g = (rho - self.R)[:, None] * e + z[:, None] * self.axis
        return g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray, *, step: float) -> tuple[np.ndarray, np.ndarray]:
        """First crossing of each ray with the torus inside the box ``[lo, hi]``.

        Sphere tracing on the exact distance (:func:`warpspec.normal_lines.first_crossing`).

        Returns:
            Hit points ``(N, 3)`` and a mask of the rays that meet the torus in the box.
        """
        return first_crossing(self.value, origins, dirs, lo, hi, step=step)


def _core_distance(params: np.ndarray, p: np.ndarray, n: np.ndarray, *,
                   radii: np.ndarray | None = None) -> np.ndarray:
    """Distance of each line ``p + s n`` from the core circle, in its meridian plane.

    With ``radii`` the distances to the core circles of those radii, ``(len(radii), M)``.
    """
    c, a, R, _ = _unpack(params)
    R = np.asarray(R if radii is None else radii, dtype=np.float64)[..., None]
    v = p - c
    z = v @ a
    radial = v - z[:, None] * a
    e = radial / np.maximum(np.linalg.norm(radial, axis=1), 1e-300)[:, None]
    P = np.stack([np.einsum("ij,ij->i", v, e), z], axis=1)
    D = np.stack([np.einsum("ij,ij->i", n, e), n @ a], axis=1)
    D /= np.maximum(np.linalg.norm(D, axis=1), 1e-300)[:, None]
    out = []
    for sign in (1.0, -1.0):  # the line may meet the core on either side of the axis
        qx, qz = sign * R - P[:, 0], -P[:, 1]
        out.append(np.abs(qx * D[:, 1] - qz * D[:, 0]))
    return np.minimum(*out)


def _unpack(params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    c = params[:3]
    theta, phi = params[3], params[4]
    a = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    return c, a, float(params[5]), float(params[6])


def _pack(torus: Torus) -> np.ndarray:
    """The seven numbers :func:`_unpack` reads: centre, the axis' polar angles, ``R``, ``r``."""
    a = torus.axis
    return np.r_[torus.centre, np.arccos(np.clip(a[2], -1.0, 1.0)), np.arctan2(a[1], a[0]),
                 torus.R, torus.r]


def _units(scale: float) -> np.ndarray:
    """The seven numbers' units in a fit: lengths in ``scale``, the same fit in any unit."""
    return np.r_[np.full(3, scale), 1.0, 1.0, scale, scale]


def fit_torus(origins: np.ndarray, dirs: np.ndarray, points: np.ndarray, *,
              scale: float, ring: bool = True) -> Torus | None:
    """Fit a ring torus to normal lines and surface points.

    Args:
        origins: A point of each normal line ``(M, 3)`` (a flash-lit ray's camera centre).
        dirs: Unit directions of the lines ``(M, 3)`` (either sense).
        points: Surface points ``(P, 3)`` (at least one fixes the tube radius).
        scale: A length of the scene (the domain's size): the residuals' robust scale is
            1/1000 of it.
        ring: Return only a ring torus (``R >= RING r``). With ``False`` any torus with
            ``R > 0`` and ``r > 0`` is returned (a spindle too): a first guess whose hits
            give the next round's normal lines, under a light whose normals move with them.

    Returns:
        The torus, or ``None`` when there are too few rays or points, or the best fit is no
        ring (``R < RING r``) and ``ring`` is asked.
    """
    from scipy.optimize import least_squares

    p = np.asarray(origins, dtype=np.float64)
    n = np.asarray(dirs, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) < MIN_RAYS or len(pts) == 0:
        return None
    c, a = best_axis(p, n)
    if c is None:
        return None
    # the core circle in the meridian planes: (R, z0) by a search over a grid, then refined
    extent = float(np.max(np.linalg.norm(pts - c, axis=1)))
    theta, phi = np.arccos(np.clip(a[2], -1.0, 1.0)), np.arctan2(a[1], a[0])
    best = (np.inf, 0.0, 0.0)
    radii = np.linspace(0.0, extent, 101)
    for z0 in np.linspace(-0.5 * extent, 0.5 * extent, 41):
        params = np.r_[c + z0 * a, theta, phi, 0.0, 0.0]
        costs = np.median(_core_distance(params, p, n, radii=radii), axis=1)
        i = int(np.argmin(costs))
        if costs[i] < best[0]:
            best = (float(costs[i]), float(radii[i]), float(z0))
    _, R, z0 = best
    c = c + z0 * a
    v = pts - c
    z = v @ a
    rho = np.linalg.norm(v - z[:, None] * a, axis=1)
    r = float(np.median(np.hypot(rho - R, z)))
    x0 = _pack(Torus(c, a, R, r))
    unit = _units(scale)  # and the residuals in ``scale`` too

    def residuals(x: np.ndarray) -> np.ndarray:
        params = x * unit
        torus = Torus(*_unpack(params))
        return np.r_[_core_distance(params, p, n), torus.value(pts)] / scale

    fit = least_squares(residuals, x0 / unit, loss="soft_l1", f_scale=1e-3, max_nfev=200)
    torus = Torus(*_unpack(fit.x * unit))
    if not (torus.r > 0.0 and torus.R > 0.0) or (ring and not torus.is_ring):
        return None
    return torus


def _normal_points(torus: Torus, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The torus' two points whose outward normal is each of ``normals`` ``(M, 3)``.

    A point with normal ``n`` lies at ``r n`` from a core point in ``n``'s meridian plane:
    the core point on ``n``'s side of the axis (outer) or across it (inner).
    """
    radial = normals - (normals @ torus.axis)[:, None] * torus.axis
    e = radial / np.maximum(np.linalg.norm(radial, axis=1), 1e-300)[:, None]
    core = torus.R * e
    tube = torus.r * normals
    return torus.centre + core + tube, torus.centre - core + tube


def first_hits(torus: Torus, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Where each ray first crosses the torus: the least positive root of its quartic.

    The quartic ``(|v|^2 + R^2 - r^2)^2 = 4 R^2 (|v|^2 - (v . a)^2)`` along ``v = o - c +
    t d`` (unit ``d``), its roots the eigenvalues of the companion matrices. A ray that misses
    (no positive real root) gets the real part of its complex root nearest to the real line,
    its nearest approach: the hit moves on continuously as the ray leaves the tube.

    Args:
        torus: The torus.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.

    Returns:
        The hits ``(M, 3)``.
    """
    w = origins - torus.centre
    wa, da = w @ torus.axis, dirs @ torus.axis
    A = np.einsum("ij,ij->i", dirs, w)
    ww = np.einsum("ij,ij->i", w, w)
    B = ww + torus.R ** 2 - torus.r ** 2
    R2 = 4.0 * torus.R ** 2
    coeffs = np.stack([4.0 * A,
                       4.0 * A ** 2 + 2.0 * B - R2 * (1.0 - da ** 2),
                       4.0 * A * B - R2 * (2.0 * A - 2.0 * wa * da),
                       B ** 2 - R2 * (ww - wa ** 2)], axis=1)
    companion = np.zeros((len(w), 4, 4))
    companion[:, 0, :] = -coeffs
    companion[:, 1, 0] = companion[:, 2, 1] = companion[:, 3, 2] = 1.0
    roots = np.linalg.eigvals(companion)
    ahead = roots.real > 0.0
    real = ahead & (np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots.real)))
    t_real = np.where(real, roots.real, np.inf).min(axis=1)
    nearest = np.where(ahead, np.abs(roots.imag), np.inf)
    t_near = np.take_along_axis(roots.real, nearest.argmin(axis=1)[:, None], axis=1)[:, 0]
    t = np.where(np.isfinite(t_real), t_real, np.where(ahead.any(axis=1), t_near, 0.0))
    return origins + t[:, None] * dirs


def pixel_misses(torus: Torus, origins: np.ndarray, dirs: np.ndarray,
                 asked: Callable[[np.ndarray], np.ndarray], pixel: np.ndarray) -> np.ndarray:
    """How far (pixels) each ray passes from the torus point with the normal it asks.

    The normal a ray asks where it first meets the torus (:func:`first_hits`); of the two
    points with that normal (outer and inner), the nearer; the ray's distance from it over
    the width of the ray's ``pixel`` (radians) at that point's depth. That is the move of the
    ray alone, not counting that the normal it asks turns with it: highlights moved by 1.8
    px were missed by a median of 1.7-2.1 px (0.9-6.6), under lamps, a point lamp and the
    flash.

    Args:
        torus: The torus.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        asked: The outward unit normals ``(M, 3)`` the rays ask at given hits ``(M, 3)``.
        pixel: Each ray's pixel, in radians ``(M,)``.

    Returns:
        The misses ``(M,)``.
    """
    hits = first_hits(torus, origins, dirs)
    return np.minimum(*(ray_misses(target, origins, dirs, pixel)
                        for target in _normal_points(torus, asked(hits))))


def refit_torus(start: Torus, origins: np.ndarray, dirs: np.ndarray,
                asked: Callable[[np.ndarray], np.ndarray], pixel: np.ndarray,
                points: np.ndarray, *, voxel: float,
                point_voxels: float = NOISY_POINT_VOXELS) -> Torus | None:
    """A torus refitted to the rays and the normals they ask, the points weighed as noisy.

    A ray should pass through the torus point whose outward normal is the one it asks
    where it meets the torus; its residual is its distance from it in pixels
    (:func:`pixel_misses`). A point's residual is its distance from the
    torus in units of ``point_voxels`` voxels. Under a light other than the flash the rays fix
    the tube's radius; by flash a ray is a normal line of every torus about one core circle,
    and only the points fix it. All seven numbers are refined together from ``start``
    (:func:`warpspec.pixel_fit.refine`).

    Args:
        start: The torus refined.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        asked: The outward unit normals ``(M, 3)`` the rays ask at given hits ``(M, 3)``.
        pixel: Each ray's pixel, in radians ``(M,)``.
        points: Surface points ``(P, 3)``.
        voxel: The grid's spacing (world units).
        point_voxels: The distance of a point from the torus that weighs as a ray a pixel
            off.

    Returns:
        The torus, or ``None`` for fewer than :data:`MIN_RAYS` rays or a fit that is no ring.
    """
    o, d, pts = as_arrays(origins, dirs, points)
    if len(o) < MIN_RAYS:
        return None

    def residuals(params: np.ndarray) -> np.ndarray:
        torus = Torus(*_unpack(params))
        return np.r_[pixel_misses(torus, o, d, asked, pixel),
                     torus.value(pts) / (point_voxels * voxel)]

    torus = Torus(*_unpack(refine(residuals, _pack(start),
                                  _units(max(start.R + start.r, voxel)))))
    if not (torus.r > 0.0 and torus.is_ring):
        return None
    return torus


def points_torus(points: np.ndarray) -> Torus | None:
    """A ring torus through the points alone: a first guess for the rounds of the fit.

    The axis is the normal of the points' best-fit plane, through the centre of the circle
    their shadows on that plane lie nearest; the core circle's radius ``R``, its height and
    the tube's radius ``r`` are those of the circle through the points' (distance from the
    axis, height) in the meridian plane. ``None`` for fewer than four points, points on a
    line, or no ring (``R < RING r``).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 4:
        return None
    c, axes = best_fit_plane(pts)
    if axes is None:
        return None
    a = axes[2]
    # the centre in that plane: the circle through the points' shadows on it (their
    # centroid is the centre only when they are spread evenly round the axis)
    xy = (pts - c) @ axes[:2].T
    x0, y0, _ = _circle_through(xy[:, 0], xy[:, 1])
    c = c + x0 * axes[0] + y0 * axes[1]
    v = pts - c
    z = v @ a
    rho = np.linalg.norm(v - z[:, None] * a, axis=1)
    # the meridian section: the circle through the points' (rho, z), its centre (R, z0)
    R, z0, r = _circle_through(rho, z)
    c = c + z0 * a
    torus = Torus(c, a, R, r)
    return torus if r > 0.0 and torus.is_ring else None


def _circle_through(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """The circle nearest to the points ``(x, y)``: its centre and radius.

    Fitted algebraically (``x^2 + y^2 = 2 cx x + 2 cy y + k``, linear least squares): exact
    for points on a circle.
    """
    A = np.stack([2.0 * x, 2.0 * y, np.ones_like(x)], axis=1)
    (cx, cy, k), *_ = np.linalg.lstsq(A, x * x + y * y, rcond=None)
    cx, cy = float(cx), float(cy)
    return cx, cy, float(np.sqrt(max(k + cx * cx + cy * cy, 0.0)))
