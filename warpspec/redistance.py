"""Signed distance and distance to a point set on NumPy arrays (docs/DESIGN.md section 6).

Thin NumPy-level wrappers around :class:`warpspec.kernels.redistance.Redistancer`: copy to the
device, run the fast sweeps, copy back.
"""

from __future__ import annotations

import functools
import numbers

import numpy as np
import warp as wp

from ._runtime import resolve_device
from .errors import InputError
from .grid import Grid
from .kernels.redistance import BAND_MODES, METHODS, Redistancer

__all__ = ["redistance", "point_distance"]


@functools.lru_cache(maxsize=2)
def _redistancer(
    shape: tuple[int, int, int],
    spacing: float,
    device: str,
    method: str,
    band: str,
    passes: int,
) -> Redistancer:
    # kept between calls (keyed by the device's alias): the planes method records thousands
    # of launches once
    return Redistancer(shape, spacing, device, method=method, band=band, passes=passes)


VOXEL_CLIP = 1e6
"""|phi| beyond this many voxel widths is clipped before redistancing (only its sign counts)."""


def _check_positive(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name}: must be a positive finite number, got {value!r}")
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise InputError(f"{name}: must be a positive finite number, got {value!r}")
    return value


def _check_options(method: str, band: str, passes: int) -> None:
    if method not in METHODS:
        raise InputError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    if band not in BAND_MODES:
        raise InputError(f"band: must be one of {', '.join(BAND_MODES)}, got {band!r}")
    if isinstance(passes, bool) or not isinstance(passes, numbers.Integral) or passes < 1:
        raise InputError(f"passes: must be a positive integer, got {passes!r}")


def redistance(
    phi: np.ndarray,
    spacing: float,
    *,
    device: str | wp.context.Device | None = None,
    method: str = "auto",
    band: str = "gradient",
    passes: int = 1,
    cap: float | None = None,
) -> np.ndarray:
    """Return the signed distance function with the same zero set as ``phi``.

    Nodes next to a sign change keep a distance measured from ``phi`` itself (``band``); all
    other nodes get the first-order fast-sweeping distance (Zhao 2005); signs are kept
    (``phi < 0`` inside). Computed in float32 on the device.

    Args:
        phi: Level set on a uniform grid, shape ``(nx, ny, nz)`` with at least 2 nodes per
            axis, float32 or float64, finite. Not modified.
        spacing: Node spacing ``h`` in world units.
        device: Warp device or its name; ``None`` picks CUDA when available, else the CPU.
        method: ``"serial"`` (one thread does the 8 sweeps: fastest on the CPU), ``"planes"``
            (parallel sweeps over the planes ``i + j + k = const``: for CUDA) or ``"auto"``
            (serial on the CPU, planes on CUDA). Both give the same numbers.
        band: Distance of the nodes next to a sign change: ``"gradient"`` (``|phi| /
            |grad phi|`` with central differences; about 0.08 h worst error within 3 h of a
            sphere at 64^3) or ``"axis"`` (the linear zero crossings along each axis combined
            as ``1 / sqrt(sum 1 / d_axis^2)``, as in scikit-fmm; about 0.35 h).
        passes: How many times the 8 sweeps are repeated (1 is enough for a distance).
        cap: If given (positive, world units), distances are computed only up to it and the
            farther nodes read ``+-cap``: the result is exactly ``sign(phi) * min(|d|, cap)``,
            and the sweeps visit only the nodes within ``cap`` of the zero set (at 128^3, a
            cap of a few voxels saves most of the time).

    Returns:
        A new array, same shape and float dtype as ``phi``.

    Raises:
        InputError: If an argument is invalid, or ``phi`` has no zero crossing (no node is
            negative while another is not, and none is exactly 0).
    """
    arr = np.asarray(phi)
    if arr.dtype not in (np.float32, np.float64):
        raise InputError(f"phi: must be a float32 or float64 array, got dtype {arr.dtype}")
    if arr.ndim != 3 or min(arr.shape) < 2:
        raise InputError(f"phi: must be 3-D with at least 2 nodes per axis, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"phi: must be finite, found {int(np.sum(~np.isfinite(arr)))} NaN/inf")
    h = _check_positive("spacing", spacing)
    _check_options(method, band, passes)
    if cap is not None:
        cap = _check_positive("cap", cap)
    dev = resolve_device(device)
    # In voxel widths: the distance scales with phi and h together, so the float32 sweeps see
    # the same numbers whatever the units. Values beyond VOXEL_CLIP voxels only say which side
    # a node is on (no grid is that wide), so they are clipped rather than overflowing.
    # (float32 input stays in float32: a quotient that overflows is clipped all the same)
    work = np.float32 if arr.dtype == np.float32 else np.float64
    with np.errstate(over="ignore", under="ignore"):
        vox = np.clip(arr / work(h), -VOXEL_CLIP, VOXEL_CLIP)
    phi32 = np.ascontiguousarray(vox, dtype=np.float32)
    negative = phi32 < 0.0
    if not (negative.any() and not negative.all()) and not np.any(phi32 == 0.0):
        side = "negative (inside)" if negative.all() else "positive (outside)"
        raise InputError(
            f"phi: has no zero crossing (every node is {side}); there is no surface to measure "
            "the distance from"
        )
    rd = _redistancer(arr.shape, 1.0, dev.alias, method, band, int(passes))
    field = wp.array(phi32, dtype=float, device=dev, copy=True)
    rd.reinitialize(field, cap=None if cap is None else cap / h)
    with np.errstate(over="ignore"):
        out = np.asarray(field.numpy().astype(work) * work(h), dtype=arr.dtype)
    if not np.all(np.isfinite(out)):
        raise InputError(
            f"spacing: distances of up to {float(np.max(np.abs(field.numpy()))) * h:.3g} do "
            f"not fit in {arr.dtype}; pass phi as float64 or express it in other units")
    return out


def point_distance(
    points: np.ndarray,
    grid: Grid,
    *,
    device: str | wp.context.Device | None = None,
    cap: float | None = None,
) -> np.ndarray:
    """Return the Euclidean distance from every grid node to the nearest of a set of points.

    The nodes around each point are seeded exactly, then fast sweeps pass every node the
    nearest of its neighbours' nearest points (closest-point fast sweeping). The result is the
    exact Euclidean distance (to float32 rounding) at almost every node; where the Voronoi
    cells of several points meet in a sliver, a rare node gets the second-nearest point (an
    error of a fraction of ``h``). Points may lie outside the grid.

    Args:
        points: World positions, shape ``(K, 3)`` with ``K >= 1``, finite.
        grid: The grid whose nodes are measured.
        device: Warp device or its name; ``None`` picks CUDA when available, else the CPU.
        cap: If given (positive), distances above it are clamped to it (``d_max``).

    Returns:
        float32 array of shape ``grid.shape``, world units.

    Raises:
        InputError: If an argument is invalid.
    """
    if not isinstance(grid, Grid):
        raise InputError(f"grid: must be a warpspec.grid.Grid, got {type(grid).__name__}")
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("points: must be a (K, 3) array of numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 1:
        raise InputError(f"points: must have shape (K, 3) with K >= 1, got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError("points: must be finite")
    if cap is not None:
        cap = _check_positive("cap", cap)
    dev = resolve_device(device)
    rd = _redistancer(grid.shape, grid.spacing, dev.alias, "auto", "gradient", 1)
    # relative to the grid origin in float64 first: float32 keeps its precision on the grid
    local = wp.array((pts - grid.origin).astype(np.float32), dtype=wp.vec3, device=dev)
    out = wp.empty(grid.shape, dtype=float, device=dev)
    rd.point_distance(local, (0.0, 0.0, 0.0), out, cap=cap)
    return np.array(out.numpy(), copy=True)
