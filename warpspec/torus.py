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

The implicit start takes the torus when the quadric does not meet the normals and the torus
does, as it would take a quadric (the same shares of rays within 3 and 10 degrees, every point
within a quarter voxel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Torus", "fit_torus"]

AXIS_DIRECTIONS = 2000
"""Candidate axis directions of the first search (spread evenly over a hemisphere)."""
MIN_RAYS = 12
"""Fewest normal lines a torus is fitted to."""
RING = 1.2
"""The fitted torus must be a ring: ``R >= RING * r`` (else it is no candidate)."""


@dataclass(frozen=True)
class Torus:
    """A ring torus: centre, unit axis, core radius ``R`` and tube radius ``r`` (world units)."""

    centre: np.ndarray
    axis: np.ndarray
    R: float
    r: float

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

        Sphere tracing on the exact distance (at least ``step / 4`` a step, so that a ray
        grazing the surface creeps past it), then bisection of the first crossing.

        Returns:
            Hit points ``(N, 3)`` and a mask of the rays that meet the torus in the box.
        """
        o = np.asarray(origins, dtype=np.float64)
        d = np.asarray(dirs, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = (lo - o) / d
            t1 = (hi - o) / d
        near = np.nanmax(np.minimum(t0, t1), axis=1).clip(min=0.0)
        far = np.nanmin(np.maximum(t0, t1), axis=1)
        t = near.copy()
        prev = near.copy()
        alive = near < far
        hit = np.zeros(len(o), dtype=bool)
        for _ in range(2000):
            idx = np.flatnonzero(alive & ~hit)
            if len(idx) == 0:
                break
            f = self.value(o[idx] + t[idx, None] * d[idx])
            crossed = f < 0.0
            hit[idx[crossed]] = True
            go = idx[~crossed]
            prev[go] = t[go]
            # the exact distance never steps over the surface; a grazing ray creeps on
            t[go] += np.maximum(f[~crossed], 0.25 * step)
            alive[go[t[go] > far[go]]] = False
        hit &= alive
        # bisection between the last point outside and the first inside
        a, b = prev, t
        for _ in range(30):
            m = 0.5 * (a + b)
            inside = self.value(o + m[:, None] * d) < 0.0
            b = np.where(inside, m, b)
            a = np.where(inside, a, m)
        return o + b[:, None] * d, hit


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - i / n)
    azimuth = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                     np.cos(polar)], axis=1)


def _axis(p: np.ndarray, n: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The line (point, direction) that the lines ``p + s n`` pass nearest (median)."""
    dirs = _fibonacci_hemisphere(AXIS_DIRECTIONS)
    m = np.cross(n[None, :, :], dirs[:, None, :])  # (D, M, 3)
    length = np.linalg.norm(m, axis=2)
    ok = length > 1e-3
    m = np.where(ok[..., None], m / np.maximum(length, 1e-300)[..., None], 0.0)
    A = np.einsum("dmi,dmj->dij", m, m) + 1e-9 * np.eye(3)  # the axis' own direction is free
    b = np.einsum("dmi,dm->di", m, np.einsum("mi,dmi->dm", p, m))
    c = np.linalg.solve(A, b[..., None])[..., 0]
    dist = np.abs(np.einsum("dmi,dmi->dm", p[None] - c[:, None], m))
    dist = np.where(ok, dist, np.nan)
    usable = ok.sum(axis=1) >= 3
    if not usable.any():
        return None, None
    cost = np.where(usable, np.nanmedian(np.where(usable[:, None], dist, 0.0), axis=1), np.inf)
    best = int(np.argmin(cost))
    return c[best], dirs[best]


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


def fit_torus(origins: np.ndarray, dirs: np.ndarray, points: np.ndarray, *,
              scale: float) -> Torus | None:
    """Fit a ring torus to normal lines and surface points.

    Args:
        origins: A point of each normal line ``(M, 3)`` (a flash-lit ray's camera centre).
        dirs: Unit directions of the lines ``(M, 3)`` (either sense).
        points: Surface points ``(P, 3)`` (at least one fixes the tube radius).
        scale: A length of the scene (the domain's size): the residuals' robust scale is
            1/1000 of it.

    Returns:
        The torus, or ``None`` when there are too few rays or points, or the best fit is no
        ring (``R < RING r``).
    """
    from scipy.optimize import least_squares

    p = np.asarray(origins, dtype=np.float64)
    n = np.asarray(dirs, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) < MIN_RAYS or len(pts) == 0:
        return None
    c, a = _axis(p, n)
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
    x0 = np.r_[c, np.arccos(np.clip(a[2], -1.0, 1.0)), np.arctan2(a[1], a[0]), R, r]

    def residuals(params: np.ndarray) -> np.ndarray:
        torus = Torus(*_unpack(params))
        return np.r_[_core_distance(params, p, n), torus.value(pts)]

    fit = least_squares(residuals, x0, loss="soft_l1", f_scale=1e-3 * scale, max_nfev=200)
    torus = Torus(*_unpack(fit.x))
    if not (torus.r > 0.0 and torus.R >= RING * torus.r):
        return None
    return torus
