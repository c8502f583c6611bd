"""An ellipsoid refitted to the rays in pixels, with the points weighed as noisy.

The quadric of the implicit start (:mod:`warpspec.quadric`) is fitted with its points held
nearly exactly, and algebraically: its gradient is made parallel to each ray's normal, rows
weighed by the gradient's size. Points a voxel off bend it away from the normals; the fit with
the points let go (:data:`warpspec.quadric.NOISY_POINT_WEIGHT`) stops short of the truth too,
on a flat ellipsoid far short: the pebble (axes 1, 0.9, 0.34), points a voxel off per axis and
half a pixel on the highlights, 75-82% of the normals within 3 degrees (a median of 1.4-2.1),
where the truth meets all of them (a median of 0.2-0.4). Its geometric refit
(:func:`refit_ellipsoid`, :mod:`warpspec.pixel_fit`) comes back to the truth's radii and
centre within 0.02 voxel from either fit. An ellipsoid's point with a given outward normal is
unique and in closed form (:meth:`Ellipsoid.normal_points`), and so is each ray's first
crossing (:meth:`Ellipsoid.first_hits`). docs/DESIGN.md section 7 says when the implicit start
takes the refit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import quadric as Q
from .pixel_fit import NOISY_POINT_VOXELS, as_arrays, ray_misses, refine

__all__ = ["MIN_RAYS", "Ellipsoid", "pixel_misses", "refit_ellipsoid"]

MIN_RAYS = 12
"""Fewest rays an ellipsoid is refitted to: its nine numbers, and some to spare."""
DEGENERATE_PIXELS = 1e6
"""The residual of every ray and point on a degenerate ellipsoid in a refit..."""
SPAN = 1e3
"""...one with a radius this many times longer or shorter than the start's longest."""


@dataclass(frozen=True)
class Ellipsoid:
    """The ellipsoid ``(x - centre)^T M (x - centre) = 1``, ``M`` positive definite.

    Attributes:
        centre: Its centre ``(3,)`` (world units).
        matrix: ``M`` ``(3, 3)`` (per squared world unit): its eigenvalues are the inverse
            squared radii.
    """

    centre: np.ndarray
    matrix: np.ndarray

    @classmethod
    def from_quadric(cls, quadric: Q.Quadric) -> Ellipsoid | None:
        """The quadric as an ellipsoid whose inside is the object's, else ``None``.

        ``None`` for a quadric that is no ellipsoid (nor a point or empty), and for one
        negative inside an ellipsoid's outside (``A`` negative definite): an object outside
        an ellipsoidal hollow, a concave face seen from within.
        """
        A, b, c = quadric.matrix()
        eig = np.linalg.eigvalsh(A)
        if not np.all(np.isfinite(eig)) or eig[0] <= 0.0:
            return None
        x0 = -0.5 * np.linalg.solve(A, b)
        k = float(x0 @ A @ x0 - c)
        if not k > 0.0:
            return None
        return cls(quadric.centre + quadric.scale * x0, A / (k * quadric.scale ** 2))

    @property
    def radii(self) -> np.ndarray:
        """The semi-axes, shortest first ``(3,)``."""
        return 1.0 / np.sqrt(np.linalg.eigvalsh(self.matrix)[::-1])

    def quadric(self, *, centre: np.ndarray, scale: float) -> Q.Quadric:
        """The ellipsoid as a quadric in the normalised frame ``centre``, ``scale``."""
        A = self.matrix * scale ** 2
        x0 = (self.centre - centre) / scale
        b = -2.0 * A @ x0
        coeffs = np.array([A[0, 0], A[1, 1], A[2, 2], A[0, 1], A[0, 2], A[1, 2], *b,
                           x0 @ A @ x0 - 1.0])
        return Q.Quadric(coeffs / np.linalg.norm(coeffs), np.asarray(centre, float), scale)

    def first_hits(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Where each ray first crosses the ellipsoid ahead, or comes nearest to it ``(M, 3)``.

        A ray that misses gets its nearest approach to the centre in the metric ``M`` (where
        the two crossings meet as the ray leaves the ellipsoid): the hit moves on
        continuously.
        """
        w = origins - self.centre
        a = np.einsum("ij,jk,ik->i", dirs, self.matrix, dirs)
        b = np.einsum("ij,jk,ik->i", dirs, self.matrix, w)
        c = np.einsum("ij,jk,ik->i", w, self.matrix, w) - 1.0
        disc = b * b - a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        # the crossing ahead: the far root from a ray that starts inside
        near = (-b - root) / a
        t = np.where(disc >= 0.0, np.where(near >= 0.0, near, (-b + root) / a), -b / a)
        return origins + t[:, None] * dirs

    def normal_points(self, normals: np.ndarray) -> np.ndarray:
        """The ellipsoid's point whose outward normal is each of ``normals`` ``(M, 3)``.

        The normal at ``x`` is along ``M (x - centre)``, so ``x - centre`` is along
        ``M^-1 n``, at unit ``M``-length.
        """
        m = np.linalg.solve(self.matrix, normals.T).T
        return self.centre + m / np.sqrt(np.maximum(np.einsum("ij,ij->i", m, normals),
                                                    1e-300))[:, None]

    def distance(self, points: np.ndarray) -> np.ndarray:
        """The points' first-order signed distances (positive outside) ``(P,)``.

        ``q / |grad q|`` of ``q(x) = (x - centre)^T M (x - centre) - 1``, as
        :meth:`warpspec.quadric.Quadric.distance` measures a quadric's.
        """
        w = points - self.centre
        g = 2.0 * w @ self.matrix
        q = np.einsum("ij,ij->i", w @ self.matrix, w) - 1.0
        return q / np.maximum(np.linalg.norm(g, axis=1), 1e-300)

    def _pack(self) -> np.ndarray:
        """Nine numbers: the centre, then ``M``'s Cholesky factor.

        The factor's entries: the log of its diagonal, then the three below it.
        """
        L = np.linalg.cholesky(self.matrix)
        return np.r_[self.centre, np.log(np.diag(L)), L[1, 0], L[2, 0], L[2, 1]]

    @classmethod
    def _unpack(cls, params: np.ndarray) -> Ellipsoid:
        """The ellipsoid of :meth:`_pack`'s nine numbers: any nine give one."""
        L = np.diag(np.exp(params[3:6]))
        L[1, 0], L[2, 0], L[2, 1] = params[6:9]
        return cls(np.asarray(params[:3], dtype=np.float64), L @ L.T)


def pixel_misses(ellipsoid: Ellipsoid, origins: np.ndarray, dirs: np.ndarray,
                 asked: Callable[[np.ndarray], np.ndarray], pixel: np.ndarray, *,
                 hits: np.ndarray | None = None) -> np.ndarray:
    """How far (pixels) each ray passes from the ellipsoid's point with the normal it asks.

    The normal a ray asks where it first meets the ellipsoid (:meth:`Ellipsoid.first_hits`);
    the ray's distance from the point with that normal over the width of the ray's ``pixel``
    at its depth (:func:`warpspec.pixel_fit.ray_misses`).

    Args:
        ellipsoid: The ellipsoid.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        asked: The outward unit normals ``(M, 3)`` the rays ask at given hits ``(M, 3)``.
        pixel: Each ray's pixel, in radians ``(M,)``.
        hits: The rays' first hits, when already found.

    Returns:
        The misses ``(M,)``.
    """
    if hits is None:
        hits = ellipsoid.first_hits(origins, dirs)
    targets = ellipsoid.normal_points(asked(hits))
    return ray_misses(targets, origins, dirs, pixel)


def refit_ellipsoid(start: Ellipsoid, origins: np.ndarray, dirs: np.ndarray,
                    asked: Callable[[np.ndarray], np.ndarray], pixel: np.ndarray,
                    points: np.ndarray, *, voxel: float,
                    point_voxels: float = NOISY_POINT_VOXELS) -> Ellipsoid | None:
    """An ellipsoid refitted to the rays and the normals they ask, the points weighed as noisy.

    A ray's residual is its pixel miss (:func:`pixel_misses`), a point's its distance from the
    ellipsoid in units of ``point_voxels`` voxels; the nine numbers (the centre and ``M``'s
    Cholesky factor, so every fit is an ellipsoid) are refined together from ``start``
    (:func:`warpspec.pixel_fit.refine`).

    Args:
        start: The ellipsoid refined.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        asked: The outward unit normals ``(M, 3)`` the rays ask at given hits ``(M, 3)``.
        pixel: Each ray's pixel, in radians ``(M,)``.
        points: Surface points ``(P, 3)``.
        voxel: The grid's spacing (world units).
        point_voxels: The distance of a point from the ellipsoid that weighs as a ray a pixel
            off.

    Returns:
        The ellipsoid, or ``None`` for fewer than :data:`MIN_RAYS` rays or a fit that is not
        finite.
    """
    o, d, pts = as_arrays(origins, dirs, points)
    if len(o) < MIN_RAYS:
        return None
    size = max(float(start.radii[-1]), voxel)

    def residuals(params: np.ndarray) -> np.ndarray:
        # a step to a degenerate ellipsoid (a quadric that is a long cylinder in the domain,
        # fitted as an ellipsoid, can stretch without end) gets residuals the fit steps back
        # from, before the rays ask the scene for normals where it would meet them
        shape = Ellipsoid._unpack(params)
        with np.errstate(all="ignore"):
            radii = shape.radii if np.all(np.isfinite(shape.matrix)) else np.full(3, np.nan)
            hits = shape.first_hits(o, d)
            if not (np.all(radii >= size / SPAN) and np.all(radii <= size * SPAN)
                    and np.all(np.isfinite(hits))):
                return np.full(len(o) + len(pts), DEGENERATE_PIXELS)
            return np.r_[pixel_misses(shape, o, d, asked, pixel, hits=hits),
                         shape.distance(pts) / (point_voxels * voxel)]

    # the centre in units of the size, the factor's log diagonal as it is, the rest per size
    unit = np.r_[np.full(3, size), np.ones(3), np.full(3, 1.0 / size)]
    fit = Ellipsoid._unpack(refine(residuals, start._pack(), unit))
    return fit if np.all(np.isfinite(fit.matrix)) and np.all(np.isfinite(fit.centre)) \
        else None
