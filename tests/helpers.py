"""Small grid helpers shared by the tests."""

import numpy as np

from warpspec.grid import Grid


def cube_grid(n: int, lo: float = -1.0, hi: float = 1.0) -> Grid:
    """A cubic grid with ``n`` cells per side over ``[lo, hi]^3``."""
    return Grid.from_bounds(np.full(3, lo), np.full(3, hi), resolution=n)


def sphere_sdf(grid: Grid, centre, radius: float) -> np.ndarray:
    """Exact signed distance to a sphere, float64."""
    x, y, z = grid.coordinates()
    c = np.asarray(centre, dtype=float)
    return np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) - radius


def interior(a: np.ndarray, width: int) -> np.ndarray:
    """The array without ``width`` nodes at every face."""
    w = width
    return a[w:-w, w:-w, w:-w]
