"""The uniform grid that carries the level set."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SceneError

__all__ = ["Grid"]


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
            raise SceneError(f"grid.origin: must be finite, got {origin.tolist()}")
        if not (np.isfinite(self.spacing) and self.spacing > 0):
            raise SceneError(f"grid.spacing: must be a positive finite number, got {self.spacing}")
        if len(self.shape) != 3 or min(self.shape) < 2:
            raise SceneError(f"grid.shape: needs at least 2 nodes per axis, got {self.shape}")

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
            SceneError: If the box is empty or inverted, or the resolution is not a positive
                integer.
        """
        if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer):
            raise SceneError(f"resolution: must be a positive integer, got {resolution!r}")
        if resolution < 2:
            raise SceneError(f"resolution: must be at least 2 cells, got {resolution}")
        lo = np.asarray(lo, dtype=np.float64).reshape(3)
        hi = np.asarray(hi, dtype=np.float64).reshape(3)
        extent = hi - lo
        if not np.all(np.isfinite(extent)) or np.any(extent <= 0):
            raise SceneError(
                f"domain: max must exceed min on every axis, got min={lo.tolist()} "
                f"max={hi.tolist()}"
            )
        h = float(extent.max()) / int(resolution)
        cells = np.maximum(np.ceil(extent / h - 1e-9).astype(int), 1)
        return cls(origin=lo, spacing=h, shape=tuple(int(c) + 1 for c in cells))

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
