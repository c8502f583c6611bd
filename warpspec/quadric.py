"""A quadric fitted to the points and to the normals where the rays meet it.

The first stage of the implicit start (see :mod:`warpspec.implicit`): ten coefficients, so the
fit is small linear algebra on the host, and a ray meets a quadric where a quadratic in its
parameter vanishes, so the intersections are exact. Spheres, ellipsoids, cylinders, planes and
paraboloids are quadrics: on such shapes the fit alone is the answer, and on others it is the
shape that the grid fit corrects. The rays' depths are unknown, so the fit alternates: intersect
the rays with the current quadric, fit the quadric whose gradient is parallel to each ray's
normal at its intersection and which vanishes at the points, and again. Rays that miss are
anchored where the quadric comes nearest along them. Every ray's weight is refitted robustly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import angle_deg
from .scene import LIGHT_POINT

__all__ = ["Quadric", "biweight", "fit_quadric", "robust_sigma"]

ROUNDS = 25
"""Intersect-and-refit rounds."""
POINT_WEIGHT = 30.0
"""Weight of ``q(y)^2 / |grad q(y)|^2`` at a point (per voxel width), against a unit normal
error: points held nearly exactly (a point a voxel off weighs as much as a normal 5.5 radians
off)."""
NOISY_POINT_WEIGHT = 1e-3
"""The same weight for points that carry noise: a point 0.55 voxel off weighs as much as a
normal a degree off, the two noises of structure from motion's points and of the highlights'
normals. See :data:`warpspec.implicit.NOISY_POINT_GAIN` for when it is used."""
MISS_WEIGHT = 0.3
"""Relative weight of a ray that misses the current quadric."""
POINT_DAMPING = 0.5
"""Under a point light the normal a ray asks moves with its hit, and the alternation can go
round between quadrics either side of the right one: a flat ellipsoid (axes 1, 0.9, 0.35)
seen all around by 28 cameras under one lamp, fitted from the truth itself, came back with
misses of 3-4 degrees on 4 of its 26 rays, its flat axis' coefficient 1.5% either side,
round after round. There each robust round's coefficients (unit length) are this much the
round before's. End to end, that scene over seeds 0-7, clean: 5 of 8 were 0.46-1.45 h off
(the quadric refused, the grid fit open), all are now 0.023-0.036 h; an ellipsoid of axes
1, 0.8, 0.6 under the lamp, seeds 0-3, clean and a quarter false, 0.017-0.038 h before and
0.017-0.019 after. The catalogue's point-lit scenes (the dome, seeds 0-7, torus-point and
ellipsoid-cap, clean, 10% and 25% false) do not change. A flash or a directional light asks
the same normal of a ray wherever it meets the quadric, and the fit is not damped."""
LIMIT_DEG = 30.0
"""Smallest Tukey limit of the quadric's robust weights in the first robust round..."""
FINAL_LIMIT_DEG = 5.0
"""...and in the last: the quadric is kept as the start only if it meets most normals within
noise (see :mod:`warpspec.implicit`), and then the others are false."""
RIDGE = 1e-6
"""Ridge on the coefficients (normalised coordinates): keeps the system regular."""


@dataclass
class Quadric:
    """``q(x) = x^T A x + b.x + c`` in coordinates ``x = (world - centre) / scale``.

    Attributes:
        coeffs: ``(A00, A11, A22, A01, A02, A12, b0, b1, b2, c)``.
        centre: World centre of the normalised frame.
        scale: World length of one normalised unit.
    """

    coeffs: np.ndarray
    centre: np.ndarray
    scale: float

    def matrix(self) -> tuple[np.ndarray, np.ndarray, float]:
        """``(A, b, c)``."""
        a = self.coeffs
        A = np.array([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]])
        return A, a[6:9].copy(), float(a[9])

    def value(self, world: np.ndarray) -> np.ndarray:
        """``q`` at world points."""
        A, b, c = self.matrix()
        x = (np.asarray(world, dtype=np.float64) - self.centre) / self.scale
        return np.einsum("ij,jk,ik->i", x, A, x) + x @ b + c

    def gradient(self, world: np.ndarray) -> np.ndarray:
        """``grad q`` (with respect to the normalised coordinates) at world points."""
        A, b, _ = self.matrix()
        x = (np.asarray(world, dtype=np.float64) - self.centre) / self.scale
        return 2.0 * x @ A + b

    def distance(self, world: np.ndarray) -> np.ndarray:
        """``|q| / |grad q|`` at world points: their first-order distance from ``q = 0``."""
        g = np.linalg.norm(self.gradient(world), axis=1)
        return np.abs(self.value(world)) / np.maximum(g, 1e-300) * self.scale

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First entry of each ray into ``q <= 0`` inside the box, or its nearest approach.

        Returns:
            Anchors ``(M, 3)``, whether each is a crossing ``(M,)``, and whether the ray enters
            the box at all ``(M,)``.
        """
        A, b, c = self.matrix()
        o = (origins - self.centre) / self.scale
        d = dirs
        t0, t1 = _slab(o, d, (lo - self.centre) / self.scale, (hi - self.centre) / self.scale)
        inside_box = t0 <= t1
        qa = np.einsum("ij,jk,ik->i", d, A, d)
        qb = 2.0 * np.einsum("ij,jk,ik->i", d, A, o) + d @ b
        qc = np.einsum("ij,jk,ik->i", o, A, o) + o @ b + c
        t = np.full(len(o), np.nan)
        crossing = np.zeros(len(o), dtype=bool)
        with np.errstate(all="ignore"):
            disc, lo_r, hi_r = _roots(qa, qb, qc)
            for r in (lo_r, hi_r):
                # an entry: q goes from + to - as t grows (derivative negative)
                deriv = 2.0 * qa * r + qb
                ok = (~crossing & inside_box & (disc >= 0) & np.isfinite(r) & (r >= t0)
                      & (r <= t1) & (deriv < 0))
                t = np.where(ok, r, t)
                crossing |= ok
            # misses: where |q| / |grad q| along the ray is smallest (sampled)
            miss = inside_box & ~crossing
            if miss.any():
                s = np.linspace(0.0, 1.0, 129)
                tt = t0[miss, None] + (t1[miss] - t0[miss])[:, None] * s[None]
                x = o[miss, None, :] + tt[..., None] * d[miss, None, :]
                qv = np.einsum("mkj,jl,mkl->mk", x, A, x) + x @ b + c
                gv = np.linalg.norm(2.0 * x @ A + b, axis=-1)
                dist = np.abs(qv) / np.maximum(gv, 1e-12)
                t[miss] = tt[np.arange(len(tt)), np.argmin(dist, axis=1)]
        anchors = self.centre + self.scale * (o + np.nan_to_num(t)[:, None] * d)
        return anchors, crossing, inside_box

    def entered_from_inside(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray,
                            hi: np.ndarray) -> np.ndarray:
        """Whether each ray enters the box inside ``q < 0`` and crosses into it again later.

        Such a ray's entry (:meth:`intersect`) lies behind a sheet of the quadric that it
        leaves the inside through first: its camera would look from within the object.
        """
        A, b, c = self.matrix()
        o = (origins - self.centre) / self.scale
        t0, _ = _slab(o, dirs, (lo - self.centre) / self.scale, (hi - self.centre) / self.scale)
        x = o + t0[:, None] * dirs
        q0 = np.einsum("ij,jk,ik->i", x, A, x) + x @ b + c
        _, crossing, inside_box = self.intersect(origins, dirs, lo, hi)
        return crossing & inside_box & (q0 < 0.0)

    def sheets_crossed(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray,
                       hi: np.ndarray) -> int:
        """Most roots of ``q`` that one ray meets inside the box (0, 1 or 2)."""
        A, b, c = self.matrix()
        o = (origins - self.centre) / self.scale
        t0, t1 = _slab(o, dirs, (lo - self.centre) / self.scale, (hi - self.centre) / self.scale)
        qa = np.einsum("ij,jk,ik->i", dirs, A, dirs)
        qb = 2.0 * np.einsum("ij,jk,ik->i", dirs, A, o) + dirs @ b
        qc = np.einsum("ij,jk,ik->i", o, A, o) + o @ b + c
        with np.errstate(all="ignore"):
            disc, lo_r, hi_r = _roots(qa, qb, qc)
            roots = np.stack([lo_r, hi_r])
            inside = (disc >= 0) & np.isfinite(roots) & (roots >= t0) & (roots <= t1) \
                & (t0 <= t1)
        return int(inside.sum(axis=0).max()) if len(o) else 0


def _roots(qa: np.ndarray, qb: np.ndarray, qc: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The discriminant and the roots (smaller, larger) of ``qa t^2 + qb t + qc`` per ray.

    Where ``q`` is linear along the ray its one root is the smaller, and the larger is NaN.
    Call under ``np.errstate(all="ignore")``.
    """
    disc = qb * qb - 4.0 * qa * qc
    sq = np.sqrt(np.maximum(disc, 0.0))
    linear = np.abs(qa) < 1e-12 * (np.abs(qb) + np.abs(qc) + 1e-300)
    r1 = np.where(linear, -qc / qb, (-qb - sq) / (2.0 * qa))
    r2 = np.where(linear, np.nan, (-qb + sq) / (2.0 * qa))
    return disc, np.fmin(r1, r2), np.where(linear, np.nan, np.fmax(r1, r2))


def _slab(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    with np.errstate(all="ignore"):
        inv = 1.0 / np.where(np.abs(d) < 1e-15, 1e-15, d)
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    t0 = np.maximum(np.max(np.minimum(ta, tb), axis=1), 0.0)
    t1 = np.min(np.maximum(ta, tb), axis=1)
    return t0, t1


def _value_rows(x: np.ndarray) -> np.ndarray:
    return np.column_stack([x[:, 0] ** 2, x[:, 1] ** 2, x[:, 2] ** 2, 2 * x[:, 0] * x[:, 1],
                            2 * x[:, 0] * x[:, 2], 2 * x[:, 1] * x[:, 2], x[:, 0], x[:, 1],
                            x[:, 2], np.ones(len(x))])


def _gradient_rows(x: np.ndarray) -> np.ndarray:
    """``(n, 3, 10)``: the Jacobian of ``grad q`` with respect to the coefficients."""
    n = len(x)
    J = np.zeros((n, 3, 10))
    J[:, 0, 0] = 2 * x[:, 0]
    J[:, 1, 1] = 2 * x[:, 1]
    J[:, 2, 2] = 2 * x[:, 2]
    J[:, 0, 3] = 2 * x[:, 1]
    J[:, 1, 3] = 2 * x[:, 0]
    J[:, 0, 4] = 2 * x[:, 2]
    J[:, 2, 4] = 2 * x[:, 0]
    J[:, 1, 5] = 2 * x[:, 2]
    J[:, 2, 5] = 2 * x[:, 1]
    J[:, 0, 6] = 1
    J[:, 1, 7] = 1
    J[:, 2, 8] = 1
    return J


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(n, u)


def height_map(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear map ``coeffs = T theta + c0`` of the quadratic height fields over a plane.

    ``q = w - (a u^2 + b uv + c v^2 + d u + e v + f)`` with ``(u, v, w) = frame @ x`` (rows: two
    unit axes of the plane and its normal, in normalised coordinates): one sheet, never two,
    which is what a surface seen from one side is.
    """
    u, v, n = frame
    T = np.zeros((10, 6))
    for col, (p, q) in enumerate(((u, u), (u, v), (v, v))):
        M = -0.5 * (np.outer(p, q) + np.outer(q, p))  # the symmetric matrix of -(p.x)(q.x)
        T[:, col] = [M[0, 0], M[1, 1], M[2, 2], M[0, 1], M[0, 2], M[1, 2], 0, 0, 0, 0]
    T[6:9, 3] = -u
    T[6:9, 4] = -v
    T[9, 5] = -1.0
    c0 = np.zeros(10)
    c0[6:9] = n
    return T, c0


def solve_quadric(points: np.ndarray, anchors: np.ndarray, normals: np.ndarray,
                  weights: np.ndarray, *, centre: np.ndarray, scale: float, voxel: float,
                  space: tuple[np.ndarray, np.ndarray] | None = None,
                  point_weight: float = POINT_WEIGHT) -> np.ndarray:
    """One weighted least-squares fit of the coefficients (normalised coordinates).

    Gradients must be parallel to the normals (two tangential equations per ray); one equation
    sets the scale (the mean of ``N . grad q`` over the rays is 1); points must lie on ``q = 0``
    to within a voxel (``point_weight`` per squared voxel of first-order distance).
    """
    rows, rhs = [], []
    x = (anchors - centre) / scale
    J = _gradient_rows(x)
    u, v = _tangents(normals)
    sw = np.sqrt(weights)[:, None]
    rows += [sw * np.einsum("ij,ijk->ik", u, J), sw * np.einsum("ij,ijk->ik", v, J)]
    rhs += [np.zeros(len(x)), np.zeros(len(x))]
    total = max(float(weights.sum()), 1e-12)
    if space is None:
        norm_row = np.einsum("i,ij,ijk->k", weights, normals, J) / total
        big = np.sqrt(max(total, 1.0)) * 10.0
        rows.append(big * norm_row[None])
        rhs.append(np.array([big]))
    if len(points):
        y = (points - centre) / scale
        # q(y) / |grad q| is the first-order distance; |grad q| ~ 1 after the scale row
        pw = np.sqrt(point_weight) * scale / voxel
        rows.append(pw * _value_rows(y))
        rhs.append(np.zeros(len(y)))
    M = np.vstack(rows)
    b = np.concatenate(rhs)
    if space is not None:
        # a height field: q = c0 + T theta, the scale fixed by the unit normal coefficient
        T, c0 = space
        b = b - M @ c0
        M = M @ T
    k = M.shape[1]
    M = np.vstack([M, np.sqrt(RIDGE) * np.eye(k)])
    b = np.concatenate([b, np.zeros(k)])
    theta, *_ = np.linalg.lstsq(M, b, rcond=None)
    return theta if space is None else c0 + T @ theta


def fit_quadric(scene, initial: Quadric, *, lo: np.ndarray, hi: np.ndarray, voxel: float,
                robust_from: int = 3, frame: np.ndarray | None = None,
                use: np.ndarray | None = None, point_weight: float = POINT_WEIGHT
                ) -> tuple[Quadric, np.ndarray, np.ndarray]:
    """Alternate intersection and fit from ``initial``.

    With ``frame`` (rows: the plane's two axes and its normal) the quadric is restricted to the
    quadratic height fields over that plane (:func:`height_map`). With ``use`` (a mask of the
    rays, ``(M,)``) only those rays are fitted; every ray's residual is measured.
    ``point_weight``: the points' weight (:data:`POINT_WEIGHT`, :data:`NOISY_POINT_WEIGHT`).

    Returns:
        The quadric, each ray's robust weight ``(M,)`` and residual angle in degrees ``(M,)``.
    """
    origins, dirs = scene.rays()
    m = len(origins)
    quad = initial
    weights = np.ones(m)
    angle = np.zeros(m)
    damping = POINT_DAMPING if m and np.any(scene.ray_lights()[0] == LIGHT_POINT) else 0.0
    for round_ in range(ROUNDS):
        anchors, crossing, inside = quad.intersect(origins, dirs, lo, hi)
        normals = scene.normals(anchors) if m else np.zeros((0, 3))
        g = quad.gradient(anchors)
        cos = np.einsum("ij,ij->i", g, normals) / np.maximum(np.linalg.norm(g, axis=1), 1e-300)
        angle = angle_deg(cos)
        angle[~inside] = 180.0
        fitted = inside if use is None else inside & use
        if round_ >= robust_from:
            # the floor of the limit falls from LIMIT_DEG to FINAL_LIMIT_DEG over the rounds:
            # on a quadric the legitimate normals end within noise and the false ones apart
            t = (round_ - robust_from) / max(ROUNDS - 1 - robust_from, 1)
            floor = LIMIT_DEG * (FINAL_LIMIT_DEG / LIMIT_DEG) ** t
            weights = robust_weights(angle, fitted, limit_deg=floor)
        else:
            weights = fitted.astype(float)
        w = weights * np.where(crossing, 1.0, MISS_WEIGHT)
        coeffs = solve_quadric(scene.points.reshape(-1, 3), anchors[fitted], normals[fitted],
                               w[fitted], centre=quad.centre, scale=quad.scale, voxel=voxel,
                               space=None if frame is None else height_map(frame),
                               point_weight=point_weight)
        if damping and round_ >= robust_from:
            before, after = (c / np.linalg.norm(c) for c in (quad.coeffs, coeffs))
            before = before if before @ after >= 0.0 else -before
            coeffs = (1.0 - damping) * after + damping * before
        quad = Quadric(coeffs, quad.centre, quad.scale)
    return quad, weights, angle


def robust_weights(angle: np.ndarray, live: np.ndarray, *, limit_deg: float,
                   tukey: float = 4.685) -> np.ndarray:
    """Tukey's biweight of the residual angles; 0 where not live.

    The limit (weight 0 beyond) is ``tukey`` robust standard deviations of the live residuals
    (``1.4826`` times their median), but never below ``limit_deg``: a model that cannot follow
    every legitimate normal (a quadric on a free-form shape, a coarse grid) must not reject
    them.
    """
    if not live.any():
        return np.zeros(len(angle))
    sigma = robust_sigma(angle[live])
    w = biweight(angle, max(tukey * sigma, limit_deg))
    w[~live] = 0.0
    return w


def robust_sigma(magnitudes: np.ndarray) -> float:
    """The robust standard deviation of residual magnitudes: 1.4826 times their median.

    For residuals that are normal about zero, ``1.4826 median(|x|)`` estimates their standard
    deviation; false ones move it only as they move the median. Zero for no values.
    """
    x = np.abs(np.asarray(magnitudes, dtype=np.float64)).ravel()
    return 1.4826 * float(np.median(x)) if len(x) else 0.0


def biweight(residual: np.ndarray, limit: float) -> np.ndarray:
    """Tukey's biweight ``(1 - (x / limit)^2)^2`` of the residuals, 0 from ``limit`` on."""
    x = np.asarray(residual, dtype=np.float64)
    return np.where(x < limit, (1.0 - (x / limit) ** 2) ** 2, 0.0)


def sphere(centre: np.ndarray, radius: float, *, frame_centre: np.ndarray, scale: float
           ) -> Quadric:
    """The sphere as a quadric in the given normalised frame."""
    c = (np.asarray(centre, float) - frame_centre) / scale
    r = radius / scale
    return Quadric(np.array([1, 1, 1, 0, 0, 0, *(-2 * c), c @ c - r * r]) / (2 * r),
                   frame_centre, scale)


def plane(point: np.ndarray, normal: np.ndarray, *, frame_centre: np.ndarray, scale: float
          ) -> Quadric:
    """The plane as a quadric in the given normalised frame."""
    p = (np.asarray(point, float) - frame_centre) / scale
    n = np.asarray(normal, float)
    return Quadric(np.array([0, 0, 0, 0, 0, 0, *n, -n @ p]), frame_centre, scale)
