"""Normal lines of highlights: the axis they pass nearest, and rays traced to a zero set.

Every normal line of a surface of revolution (a torus, a bottle) meets its axis; with a flash
at the camera a highlight's ray is a normal line. Shared by :mod:`warpspec.torus` and
:mod:`warpspec.revolution`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["best_axis", "first_crossing"]

AXIS_DIRECTIONS = 2000
"""Candidate axis directions of the first search (spread evenly over a hemisphere)."""


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - i / n)
    azimuth = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                     np.cos(polar)], axis=1)


def best_axis(p: np.ndarray, n: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
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


def first_crossing(value: Callable[[np.ndarray], np.ndarray], origins: np.ndarray,
                   dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, step: float,
                   safety: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """First crossing of each ray with the zero set of a distance-like ``value`` in a box.

    Sphere tracing (steps of ``safety`` times the value, at least ``step / 4``, so that a ray
    grazing the surface creeps past it), then bisection of the first crossing.

    Returns:
        Hit points ``(N, 3)`` and a mask of the rays that cross inside the box ``[lo, hi]``.
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
    for _ in range(4000):
        idx = np.flatnonzero(alive & ~hit)
        if len(idx) == 0:
            break
        f = value(o[idx] + t[idx, None] * d[idx])
        crossed = f < 0.0
        hit[idx[crossed]] = True
        go = idx[~crossed]
        prev[go] = t[go]
        t[go] += np.maximum(safety * f[~crossed], 0.25 * step)
        alive[go[t[go] > far[go]]] = False
    hit &= alive
    a, b = prev, t
    for _ in range(30):
        m = 0.5 * (a + b)
        inside = value(o + m[:, None] * d) < 0.0
        b = np.where(inside, m, b)
        a = np.where(inside, a, m)
    return o + b[:, None] * d, hit
