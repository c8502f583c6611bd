"""Grid coordinates and trilinear sampling of a field at world positions.

Node ``(i, j, k)`` stands at ``origin + h * (i, j, k)``; positions outside the grid are
clamped to its cells.
"""

from __future__ import annotations

import warp as wp

from .stencils import central_gradient

wp.set_module_options({"enable_backward": False})

__all__ = [
    "cell_corner",
    "corner_weight",
    "grid_coordinate",
    "trilinear",
    "trilinear_gradient",
]

@wp.func
def grid_coordinate(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> wp.vec3:
    """Continuous grid index of a world point, clamped to the grid."""
    q = (x - origin) / h
    return wp.vec3(
        wp.clamp(q[0], 0.0, float(phi.shape[0] - 1)),
        wp.clamp(q[1], 0.0, float(phi.shape[1] - 1)),
        wp.clamp(q[2], 0.0, float(phi.shape[2] - 1)),
    )

@wp.func
def cell_corner(phi: wp.array3d[float], q: wp.vec3) -> wp.vec3i:
    """Lowest node of the cell that holds the continuous index ``q``."""
    return wp.vec3i(
        wp.min(int(q[0]), phi.shape[0] - 2),
        wp.min(int(q[1]), phi.shape[1] - 2),
        wp.min(int(q[2]), phi.shape[2] - 2),
    )

@wp.func
def corner_weight(f: wp.vec3, c: int) -> float:
    """Trilinear weight of corner ``c`` (bits: x, y, z) for fractions ``f`` in the cell."""
    w = wp.where((c & 1) == 1, f[0], 1.0 - f[0])
    w *= wp.where(((c >> 1) & 1) == 1, f[1], 1.0 - f[1])
    w *= wp.where(((c >> 2) & 1) == 1, f[2], 1.0 - f[2])
    return w

@wp.func
def trilinear(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> float:
    """Trilinear interpolation of a nodal field at a world point (clamped to the grid)."""
    q = grid_coordinate(phi, origin, h, x)
    n = cell_corner(phi, q)
    f = q - wp.vec3(float(n[0]), float(n[1]), float(n[2]))
    value = float(0.0)
    for c in range(8):
        value += corner_weight(f, c) * phi[n[0] + (c & 1), n[1] + ((c >> 1) & 1),
                                           n[2] + ((c >> 2) & 1)]
    return value

@wp.func
def trilinear_gradient(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> wp.vec3:
    """Trilinear interpolation of the nodal central-difference gradients at a world point."""
    q = grid_coordinate(phi, origin, h, x)
    n = cell_corner(phi, q)
    f = q - wp.vec3(float(n[0]), float(n[1]), float(n[2]))
    g = wp.vec3(0.0, 0.0, 0.0)
    for c in range(8):
        g += corner_weight(f, c) * central_gradient(phi, n[0] + (c & 1), n[1] + ((c >> 1) & 1),
                                                     n[2] + ((c >> 2) & 1), 0.5 / h)
    return g
