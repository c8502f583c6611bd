"""A surface of revolution fitted to the normal lines of highlights: bottles, vases, cans.

Every normal line of a surface of revolution meets its axis. With a flash at the camera a
highlight's ray is a normal line; under another light the implicit start passes the normal line
through the ray's current hit, fitting and intersecting in turn (as for the torus). Rotational
symmetry makes sparse data go far: each point gives the profile's radius at its height all the
way round, and each normal line the profile's slope where it meets the profile. The fit
(docs/DESIGN.md section 7):

1. the axis: the line the normal lines pass nearest (the torus' search over 2,000 directions),
   refined by robust least squares (scipy's ``soft_l1`` loss); a line that passes farther than
   :data:`AXIS_VOXELS` voxels from it belongs to no surface of revolution about this axis (a
   false highlight) and is left out;
2. the profile ``r(h)``: radii on knots half a voxel apart along the axis over the domain,
   fitted by least squares to the points' radii and to the lines' slopes where each line
   first meets the current profile, with the third-order energy ``|r'''|^2`` as smoothness
   (its null space holds every quadratic profile, so a cone or a paraboloid costs nothing);
   lines are met again and the profile refitted :data:`PROFILE_ROUNDS` times, each slope
   weighed by Tukey's biweight of its angle.

The implicit start takes the surface when the quadric and the torus do not meet the normals and
it does, as it would take a quadric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import plane_frame
from .normal_lines import best_axis, first_crossing

__all__ = ["SurfaceOfRevolution", "fit_revolution"]

MIN_RAYS = 12
"""Fewest normal lines near one axis a surface of revolution is fitted to."""
AXIS_VOXELS = 0.5
"""A normal line passing farther than this many voxels from the axis is left out."""
AXIS_SHARE = 0.5
"""At least this share of the normal lines must pass the axis within AXIS_VOXELS."""
AXIS_SIGMAS = 6.0
"""Once the axis is refined, a line is kept within this many robust deviations of the kept
lines' distances from it (between AXIS_FLOOR and AXIS_VOXELS voxels)."""
AXIS_FLOOR = 0.05
KNOT_VOXELS = 0.5
"""Spacing of the profile's knots along the axis, in voxels."""
PROFILE_ROUNDS = 20
"""Intersect-and-refit rounds of the profile."""
PROFILE_SMOOTHNESS = 1e-6
"""Weight of the third-order energy of the profile, lengths in units of the domain's size."""
POINT_WEIGHT = 20.0
"""Weight of a point's radius error in voxels, against 1 for a unit error of a line's slope."""
SLOPE_LIMIT_DEG = 20.0
"""Tukey limit of a line's slope weight (the angle between its direction and the normal)."""


@dataclass(frozen=True)
class SurfaceOfRevolution:
    """A surface of revolution: a point and unit direction of its axis, and its profile.

    Attributes:
        base: The axis' point at height 0 ``(3,)``.
        axis: Unit axis direction ``(3,)``.
        heights: Heights of the profile's knots along the axis (evenly spaced, increasing).
        radii: The profile's radius at each knot (``>= 0``).
    """

    base: np.ndarray
    axis: np.ndarray
    heights: np.ndarray
    radii: np.ndarray

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height, distance from the axis and the unit radial direction of points ``(N, 3)``."""
        v = np.asarray(x, dtype=np.float64).reshape(-1, 3) - self.base
        h = v @ self.axis
        radial = v - h[:, None] * self.axis
        rho = np.linalg.norm(radial, axis=1)
        e = radial / np.maximum(rho, 1e-300)[:, None]
        return h, rho, e

    def slopes(self) -> np.ndarray:
        """``r'`` at each knot."""
        return np.gradient(self.radii, self.heights)

    def value(self, x: np.ndarray) -> np.ndarray:
        """First-order signed distance ``(rho - r(h)) / sqrt(1 + r'(h)^2)`` (negative inside)."""
        h, rho, _ = self.split(x)
        r = np.interp(h, self.heights, self.radii)
        s = np.interp(h, self.heights, self.slopes())
        return (rho - r) / np.sqrt(1.0 + s * s)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal of the profile at the points' heights ``(N, 3)``."""
        h, _, e = self.split(x)
        s = np.interp(h, self.heights, self.slopes())
        g = e - s[:, None] * self.axis
        return g / np.linalg.norm(g, axis=1, keepdims=True)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray, *, step: float) -> tuple[np.ndarray, np.ndarray]:
        """First crossing of each ray with the surface in the box ``[lo, hi]``.

        Sphere tracing at half the first-order distance
        (:func:`warpspec.normal_lines.first_crossing`).
        """
        return first_crossing(self.value, origins, dirs, lo, hi, step=step, safety=0.5)


def _line_axis_distance(c: np.ndarray, a: np.ndarray, p: np.ndarray,
                        n: np.ndarray) -> np.ndarray:
    """Distance between each line ``p + s n`` and the axis line ``c + s a``."""
    m = np.cross(n, a)
    length = np.linalg.norm(m, axis=1)
    along = np.linalg.norm(np.cross(p - c, a), axis=1)  # a line parallel to the axis
    with np.errstate(invalid="ignore", divide="ignore"):
        skew = np.abs(np.einsum("ij,ij->i", p - c, m)) / length
    return np.where(length > 1e-9, skew, along)


def _refine_axis(c: np.ndarray, a: np.ndarray, p: np.ndarray, n: np.ndarray,
                 voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Robust least squares of the lines' distances from the axis, in voxels.

    soft_l1 with scale AXIS_VOXELS / 2; the axis' point moves in voxels, so any unit fits alike.
    """
    from scipy.optimize import least_squares

    u, w = plane_frame(a)[:2]

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = a + x[2] * u + x[3] * w
        return c + voxel * (x[0] * u + x[1] * w), d / np.linalg.norm(d)

    fit = least_squares(lambda x: _line_axis_distance(*unpack(x), p, n) / voxel, np.zeros(4),
                        loss="soft_l1", f_scale=0.5 * AXIS_VOXELS, max_nfev=200)
    return unpack(fit.x)


def fit_revolution(starts: np.ndarray, dirs: np.ndarray, points: np.ndarray, *,
                   lo: np.ndarray, hi: np.ndarray, voxel: float
                   ) -> tuple[SurfaceOfRevolution | None, np.ndarray]:
    """Fit a surface of revolution to normal lines and surface points.

    Args:
        starts: A point of each normal line outside the surface ``(M, 3)`` (a flash-lit ray's
            camera centre).
        dirs: Unit directions of the lines, inward from ``starts`` ``(M, 3)``.
        points: Surface points ``(P, 3)``.
        lo: The domain's lower corner.
        hi: The domain's upper corner.
        voxel: The grid's spacing.

    Returns:
        The surface (or ``None`` when fewer than :data:`MIN_RAYS` lines, or less than
        :data:`AXIS_SHARE` of them, pass near one axis, or there is no point) and the mask of
        the lines it was fitted to.
    """
    p = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    none = np.zeros(len(p), dtype=bool)
    if len(p) < MIN_RAYS or len(pts) == 0:
        return None, none
    c, a = best_axis(p, n)
    if c is None:
        return None, none
    c, a = _refine_axis(c, a, p, n, voxel)
    near = _line_axis_distance(c, a, p, n) <= AXIS_VOXELS * voxel
    if near.sum() < MIN_RAYS or near.mean() < AXIS_SHARE:
        return None, near
    for _ in range(2):
        # refit to the lines near the axis, then keep those within a few robust deviations
        c, a = _refine_axis(c, a, p[near], n[near], voxel)
        dist = _line_axis_distance(c, a, p, n)
        spread = AXIS_SIGMAS * 1.4826 * float(np.median(dist[near]))
        near = dist <= np.clip(spread, AXIS_FLOOR * voxel, AXIS_VOXELS * voxel)
        if near.sum() < MIN_RAYS:
            return None, near
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])], dtype=np.float64)
    span = (corners - c) @ a
    step = KNOT_VOXELS * voxel
    count = int(np.ceil((span.max() - span.min()) / step)) + 1
    heights = span.min() + step * np.arange(count)
    profile = SurfaceOfRevolution(c, a, heights, np.zeros(count))
    ph, prho, _ = profile.split(pts)
    keep = (ph >= heights[0]) & (ph <= heights[-1])
    if not keep.any():
        return None, near
    radii = _fit_profile(profile, ph[keep], prho[keep], p[near], n[near],
                         scale=float(np.max(np.asarray(hi) - np.asarray(lo))), voxel=voxel)
    return SurfaceOfRevolution(c, a, heights, radii), near


def _fit_profile(profile: SurfaceOfRevolution, ph: np.ndarray, prho: np.ndarray,
                 p: np.ndarray, n: np.ndarray, *, scale: float, voxel: float) -> np.ndarray:
    """The profile's radii: points' radii, lines' slopes where they meet it, smooth."""
    heights = profile.heights
    count = len(heights)
    step = heights[1] - heights[0]
    # heights and radii in units of the domain's size: the smoothness weight is scale-free
    k = step / scale
    d3 = np.diff(np.eye(count), n=3, axis=0) / k**3
    smooth = np.sqrt(PROFILE_SMOOTHNESS * k) * d3 / scale

    def rows_at(h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u = np.clip((h - heights[0]) / step, 0.0, count - 1 - 1e-9)
        i = np.floor(u).astype(int)
        return i, u - i, np.ones_like(u)

    radii = np.full(count, float(np.median(prho)))
    weights = np.ones(len(p))
    far = 2.0 * scale
    for round_ in range(PROFILE_ROUNDS):
        current = SurfaceOfRevolution(profile.base, profile.axis, heights, radii)
        hits, met = first_crossing(current.value, p, n, p - far * n, p + far * n,
                                   step=voxel, safety=0.5)
        hh, _, e = current.split(hits)
        # the outward normal (-n) in the meridian plane: nh + nr r' = 0 along the profile
        nh, nr = -(n @ profile.axis), -np.einsum("ij,ij->i", n, e)
        use = met & (weights > 0.0) & (hh >= heights[0]) & (hh <= heights[-1])
        A = np.zeros((len(ph) + int(use.sum()), count))
        b = np.zeros(len(A))
        i, t, _ = rows_at(ph)
        rows = np.arange(len(ph))
        w = POINT_WEIGHT / voxel
        A[rows, i] = w * (1.0 - t)
        A[rows, i + 1] = w * t
        b[: len(ph)] = w * prho
        i, _, _ = rows_at(hh[use])
        rows = len(ph) + np.arange(int(use.sum()))
        sw = np.sqrt(weights[use])
        A[rows, i] = -sw * nr[use] / step
        A[rows, i + 1] = sw * nr[use] / step
        b[rows] = -sw * nh[use]
        radii = np.linalg.lstsq(np.vstack([A, smooth]), np.r_[b, np.zeros(len(smooth))],
                                rcond=None)[0]
        radii = np.maximum(radii, 0.0)
        # Tukey weights of the slopes' angles on the new profile
        current = SurfaceOfRevolution(profile.base, profile.axis, heights, radii)
        cos = np.abs(np.einsum("ij,ij->i", current.gradient(hits), n))
        angle = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
        # every line counts fully until the profile has taken its shape, then robustly
        tukey = np.where(angle < SLOPE_LIMIT_DEG, (1.0 - (angle / SLOPE_LIMIT_DEG) ** 2) ** 2, 0.0)
        weights = np.where(met, tukey if round_ >= PROFILE_ROUNDS // 2 else 1.0, 0.0)
    # beyond the data the third-order energy would carry the curvature on (a neck closing
    # on the axis); the profile goes straight on from its last datum instead
    seen = np.r_[ph, hh[met & (weights > 0.0)]]
    first = int(np.clip(np.searchsorted(heights, seen.min()), 1, count - 2))
    last = int(np.clip(np.searchsorted(heights, seen.max()), 1, count - 2))
    slope = np.gradient(radii, step)
    radii[:first] = radii[first] + slope[first] * (heights[:first] - heights[first])
    radii[last + 1:] = radii[last] + slope[last] * (heights[last + 1:] - heights[last])
    return np.maximum(radii, 0.0)
