"""The uniform grid that carries the level set."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError

__all__ = ["MAX_NODES", "MAX_RESOLUTION", "Grid"]

MAX_NODES = 2**31 - 1
"""Most nodes a grid may have: Warp indexes arrays with 32-bit integers."""
MAX_RESOLUTION = 2048
"""Most cells along the longest side (2048^3 nodes would already need 250 GiB)."""
FLOAT32_RANGE = (1e-30, 1e30)
"""Spacing and coordinates the float32 kernels carry without underflow or overflow."""


@dataclass(frozen=True)
class Grid:
    """A uniform grid: node ``(i, j, k)`` sits at ``origin + spacing * (i, j, k)``.

    Attributes:
        origin: World position of node ``(0, 0, 0)``, shape ``(3,)``.
        spacing: Node spacing ``h`` in world units, the same on every axis.
        shape: Number of nodes along each axis.
    """

    origin: np.ndarray
    spacing: float
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "spacing", float(self.spacing))
        object.__setattr__(self, "shape", tuple(int(s) for s in self.shape))
        if not np.all(np.isfinite(origin)):
            raise InputError(f"grid.origin: must be finite, got {origin.tolist()}")
        if not (np.isfinite(self.spacing) and self.spacing > 0):
            raise InputError(f"grid.spacing: must be a positive finite number, got {self.spacing}")
        if len(self.shape) != 3 or min(self.shape) < 2:
            raise InputError(f"grid.shape: needs at least 2 nodes per axis, got {self.shape}")
        nodes = math.prod(self.shape)
        if nodes > MAX_NODES:
            raise InputError(
                f"resolution: a {'x'.join(map(str, self.shape))} grid has {nodes:.3g} nodes, "
                f"more than the {MAX_NODES:.3g} Warp can index; lower the resolution")
        lo, hi = FLOAT32_RANGE
        far = float(np.max(np.abs(origin) + self.spacing * (np.asarray(self.shape) - 1)))
        if not lo <= self.spacing <= hi or far > hi:
            raise InputError(
                f"domain: a voxel width of {self.spacing:.3g} with coordinates up to {far:.3g} "
                f"is outside what the float32 kernels carry ({lo:g} to {hi:g}); express the "
                "scene in other units (metres or millimetres)")

    @classmethod
    def from_bounds(
        cls, lo: np.ndarray, hi: np.ndarray, *, resolution: int
    ) -> Grid:
        """Cover the box ``[lo, hi]`` with ``resolution`` cells along its longest side.

        Args:
            lo: Lower corner of the box.
            hi: Upper corner of the box.
            resolution: Number of cells along the longest side of the box.

        Raises:
            InputError: If the box is empty or inverted, or the resolution is not a positive
                integer.
        """
        if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer):
            raise InputError(f"resolution: must be a positive integer, got {resolution!r}")
        if resolution < 2:
            raise InputError(f"resolution: must be at least 2 cells, got {resolution}")
        if resolution > MAX_RESOLUTION:
            raise InputError(f"resolution: must be at most {MAX_RESOLUTION} cells, got "
                             f"{resolution}")
        lo = np.asarray(lo, dtype=np.float64).reshape(3)
        hi = np.asarray(hi, dtype=np.float64).reshape(3)
        with np.errstate(over="ignore", invalid="ignore"):
            extent = hi - lo
        if not np.all(np.isfinite(extent)) or np.any(extent <= 0):
            raise InputError(
                f"domain: max must exceed min on every axis, got min={lo.tolist()} "
                f"max={hi.tolist()}"
            )
        h = float(extent.max()) / int(resolution)
        if not h > 0:
            raise InputError(f"domain: its extent {extent.max():.3g} is too small to divide "
                             f"into {resolution} cells; express the scene in other units")
        cells = np.maximum(np.ceil(np.minimum(extent / h, resolution) - 1e-9).astype(int), 1)
        return cls(origin=lo, spacing=h, shape=tuple(int(c) + 1 for c in cells))

    def __repr__(self) -> str:
        o = ", ".join(f"{v:.6g}" for v in self.origin)
        return (f"Grid(shape={'x'.join(map(str, self.shape))}, spacing={self.spacing:.6g}, "
                f"origin=({o}))")

    @property
    def upper(self) -> np.ndarray:
        """World position of the last node."""
        return self.origin + self.spacing * (np.asarray(self.shape) - 1)

    @property
    def size(self) -> int:
        """Number of nodes."""
        return int(np.prod(self.shape))

    def coordinates(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World coordinates of every node as three arrays indexed ``[i, j, k]``."""
        axes = [self.origin[a] + self.spacing * np.arange(self.shape[a]) for a in range(3)]
        return tuple(np.meshgrid(*axes, indexing="ij"))

    def to_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous grid index of world points (``(x - origin) / h``)."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.spacing
