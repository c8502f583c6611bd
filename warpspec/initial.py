"""A height field fitted to points and normals (the height start)."""

from __future__ import annotations

import numpy as np

__all__ = ["HeightFit", "fit_height_field"]

POINT_WEIGHT = 1.0e4


def monomials(degree: int) -> np.ndarray:
    """Exponent pairs ``(a, b)`` of the monomials ``u^a v^b`` of total degree at most ``degree``."""
    return np.array([(a, t - a) for t in range(degree + 1) for a in range(t, -1, -1)],
                    dtype=np.int32)


class HeightFit:
    """A polynomial height field ``w = z(u, v)`` over a plane, in the plane's frame.

    Attributes:
        point: A point of the plane (its origin).
        frame: Rows ``u``, ``v`` axes and the normal.
        scale: Length that makes ``u / scale`` and ``v / scale`` of order one.
        powers: Monomial exponents, ``(m, 2)``.
        coeffs: Coefficients of ``scale * (u/scale)^a (v/scale)^b``.
    """

    def __init__(self, point, frame, scale, powers, coeffs) -> None:
        self.point = np.asarray(point, dtype=np.float64)
        self.frame = np.asarray(frame, dtype=np.float64)
        self.scale = float(scale)
        self.powers = np.asarray(powers, dtype=np.int32)
        self.coeffs = np.asarray(coeffs, dtype=np.float64)

    def coefficient_matrix(self) -> np.ndarray:
        """The coefficients as a square matrix ``C[a, b]`` of ``u^a v^b`` (zero where unused)."""
        top = int(self.powers.max()) if len(self.powers) else 0
        out = np.zeros((top + 1, top + 1))
        out[self.powers[:, 0], self.powers[:, 1]] = self.coeffs
        return out

    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """The first-order signed distance of world points ``x`` (n, 3) to the field."""
        uvw = (np.asarray(x, dtype=np.float64) - self.point) @ self.frame.T
        s = uvw[:, :2] / self.scale
        a, b = self.powers[:, 0], self.powers[:, 1]
        u, v = s[:, :1], s[:, 1:]
        z = (u**a * v**b) @ self.coeffs
        zu = (np.where(a > 0, a * u ** np.maximum(a - 1, 0), 0.0) * v**b) @ self.coeffs
        zv = (np.where(b > 0, b * v ** np.maximum(b - 1, 0), 0.0) * u**a) @ self.coeffs
        return (uvw[:, 2] - self.scale * z) / np.sqrt(1.0 + zu**2 + zv**2)



def _design(uv: np.ndarray, powers: np.ndarray, scale: float, derivative: int | None):
    s = uv / scale
    a = powers[:, 0][None, :]
    b = powers[:, 1][None, :]
    u = s[:, :1]
    v = s[:, 1:2]
    if derivative is None:
        return scale * u**a * v**b
    if derivative == 0:
        return np.where(a > 0, a * u ** np.maximum(a - 1, 0) * v**b, 0.0)
    return np.where(b > 0, b * u**a * v ** np.maximum(b - 1, 0), 0.0)


def fit_height_field(
    point: np.ndarray,
    frame: np.ndarray,
    scale: float,
    points: np.ndarray,
    hits: np.ndarray,
    normals: np.ndarray,
    *,
    degree: int = 4,
    smoothing: float = 1e-4,
) -> HeightFit:
    """Least-squares height field through ``points`` whose slopes match ``normals`` at ``hits``.

    Each normal ``N`` at ``(u, v)`` asks for ``z_u = -N.u / N.n`` and ``z_v = -N.v / N.n``;
    normals within 80 degrees of the plane are left out. Points weigh :data:`POINT_WEIGHT`
    times a slope equation, so the field interpolates them: the point term of the flow holds
    the zero set where it is but cannot pull it onto a point it misses. The degree drops until
    the equations outnumber the unknowns; ``smoothing`` is a ridge on the coefficients above
    degree one.
    """
    n_eq = 2 * len(hits) + len(points)
    while degree > 1 and len(monomials(degree)) > max(n_eq // 2, 3):
        degree -= 1
    powers = monomials(degree)
    rows, rhs = [], []
    if len(points):
        uvw = (points - point) @ frame.T
        rows.append(POINT_WEIGHT * _design(uvw[:, :2], powers, scale, None) / scale)
        rhs.append(POINT_WEIGHT * uvw[:, 2] / scale)
    if len(hits):
        uvw = (hits - point) @ frame.T
        nn = normals @ frame.T
        ok = nn[:, 2] > np.cos(np.radians(80.0))
        for axis in (0, 1):
            rows.append(_design(uvw[ok, :2], powers, scale, axis))
            rhs.append(-nn[ok, axis] / nn[ok, 2])
    high = np.array([a + b >= 2 for a, b in powers], dtype=float)
    rows.append(np.sqrt(smoothing) * np.diag(high))
    rhs.append(np.zeros(len(powers)))
    coeffs, *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
    return HeightFit(point, frame, scale, powers, coeffs)
