"""Closed-form shapes refitted to the rays in pixels, with the points weighed as noisy.

A shape fitted with its points held exactly bends away from the highlights when the points
carry noise, as those of structure from motion do. A refit weighs the two noises alike: each
ray should pass through the shape's point whose outward normal is the one the ray asks where
it meets the shape, and its residual is its distance from that point in pixels
(:func:`ray_misses`); a point's residual is its distance from the shape, a voxel
(:data:`NOISY_POINT_VOXELS`) weighing as a pixel. All the shape's numbers are refined together
by robust least squares (:func:`refine`). The torus (:func:`warpspec.torus.refit_torus`) and
the ellipsoid (:func:`warpspec.ellipsoid.refit_ellipsoid`) are refitted so; docs/DESIGN.md
section 7 says when the implicit start takes a refit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["NOISY_POINT_VOXELS", "ROBUST_PIXELS", "as_arrays", "point_pixels", "ray_misses",
           "refine"]

NOISY_POINT_VOXELS = 1.0
"""A point this many voxels off the shape weighs as much as a ray a pixel off
(:func:`ray_misses`): the two noises of structure from motion's points and of the highlights.
Tori under lamps and a point lamp, seeds 0-3, eight points a voxel off per axis, 56 refits
from tori up to 1.7 voxels off: the tube within 0.02 voxel of the truth in every one; with the
points weighed four times more, a median of 0.06 voxel off and at worst 0.15."""
ROBUST_PIXELS = 10.0
"""The robust loss' scale (pixels): beyond it a ray weighs less and less. At 1 px the fit is
nearly one of least absolute values and stops short: 6 of the 56 torus refits above 0.1-0.7
voxel off, at 3 px one (0.1), at 10 and 30 px none beyond 0.02."""
MAX_EVALUATIONS = 200
"""Most evaluations of the residuals in one refit."""


def as_arrays(origins: np.ndarray, dirs: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rays' origins and directions and the points, as float64 ``(N, 3)`` arrays."""
    return tuple(np.asarray(x, dtype=np.float64).reshape(-1, 3)
                 for x in (origins, dirs, points))


def ray_misses(targets: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
               pixel: np.ndarray) -> np.ndarray:
    """How far (pixels) each ray passes from its target point.

    The distance of the point from the ray's line over the width of the ray's pixel at the
    point's depth.

    Args:
        targets: One point per ray ``(M, 3)``.
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        pixel: Each ray's pixel, in radians ``(M,)`` (:meth:`warpspec.Scene.pixel_angles`).

    Returns:
        The misses ``(M,)``.
    """
    v = targets - origins
    depth = np.maximum(np.einsum("ij,ij->i", v, dirs), 1e-12)
    return np.linalg.norm(np.cross(v, dirs), axis=1) / (depth * pixel)


def point_pixels(distance: np.ndarray, points: np.ndarray, centres: np.ndarray,
                 pixel: float) -> np.ndarray:
    """Points' distances from a shape as the pixels they span in the cameras.

    A distance over the width of a pixel at the point's depth, the median of its distances
    from the cameras' centres.

    Args:
        distance: Each point's distance from the shape (world units) ``(P,)``.
        points: The points ``(P, 3)``.
        centres: The cameras' centres ``(K, 3)``.
        pixel: A pixel, in radians (:meth:`warpspec.Scene.pixel_angles`).

    Returns:
        The distances in pixels ``(P,)``.
    """
    depth = np.median(np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=2), axis=1)
    return np.abs(distance) / (depth * pixel)


def refine(residuals: Callable[[np.ndarray], np.ndarray], start: np.ndarray,
           unit: np.ndarray) -> np.ndarray:
    """The numbers that minimise the robust sum of ``residuals``, from ``start``.

    scipy's ``soft_l1`` loss at the scale :data:`ROBUST_PIXELS`, the numbers in ``unit`` (so
    that the fit is the same in any unit of length).

    Args:
        residuals: Residuals (pixels, or points' distances in :data:`NOISY_POINT_VOXELS`) of
            the shape the numbers describe.
        start: The numbers refined.
        unit: Each number's unit.

    Returns:
        The refined numbers.
    """
    from scipy.optimize import least_squares

    fit = least_squares(lambda x: residuals(x * unit), start / unit, loss="soft_l1",
                        f_scale=ROBUST_PIXELS, max_nfev=MAX_EVALUATIONS)
    return fit.x * unit
