"""Starting surfaces on the grid: the paper's plane and bend, a height field, a blend.

Each fills a level set from a closed form (:mod:`warpspec.solver.starts` drives them); the
implicit start's own fields live in :mod:`warpspec.kernels.implicit`.
"""

from __future__ import annotations

import warp as wp

from .constraints import node_position
from .stencils import central_gradient

wp.set_module_options({"enable_backward": False})

__all__ = [
    "launch_bend",
    "launch_blend",
    "launch_height_field",
    "launch_plane",
]

@wp.kernel
def plane_field(
    origin: wp.vec3, h: float, point: wp.vec3, normal: wp.vec3, phi: wp.array3d[float]
):
    """Signed distance to the plane through ``point`` with unit ``normal`` (positive side)."""
    i, j, k = wp.tid()
    phi[i, j, k] = wp.dot(node_position(origin, h, i, j, k) - point, normal)

@wp.kernel
def bend_field(
    phi: wp.array3d[float], dist: wp.array3d[float], h: float, c: float,
    out: wp.array3d[float],
):
    """``phi - c * d * |grad phi|`` (paper eq. 23): keeps the zero set on the points."""
    i, j, k = wp.tid()
    g = wp.length(central_gradient(phi, i, j, k, 0.5 / h))
    out[i, j, k] = phi[i, j, k] - c * dist[i, j, k] * g

@wp.kernel
def height_field(
    origin: wp.vec3,
    h: float,
    point: wp.vec3,
    axis_u: wp.vec3,
    axis_v: wp.vec3,
    normal: wp.vec3,
    scale: float,
    coeffs: wp.array2d[float],
    phi: wp.array3d[float],
):
    """Signed distance (to first order) to the height field ``w = z(u, v)`` over a plane.

    ``z = scale * sum_ab coeffs[a, b] (u/scale)^a (v/scale)^b`` in the plane's frame; the value
    is ``(w - z) / sqrt(1 + |grad z|^2)``, positive on the ``normal`` side. One thread fills
    a column of nodes along the last axis; the polynomial and its two partial derivatives
    are evaluated by nested Horner schemes.
    """
    i, j = wp.tid()
    top = coeffs.shape[0] - 1
    for k in range(phi.shape[2]):
        d = node_position(origin, h, i, j, k) - point
        u = wp.dot(d, axis_u) / scale
        v = wp.dot(d, axis_v) / scale
        z = float(0.0)
        zu = float(0.0)
        zv = float(0.0)
        for ia in range(top + 1):
            a = top - ia
            p = float(0.0)  # P_a(v) = sum_b coeffs[a, b] v^b, and its derivative
            dp = float(0.0)
            for ib in range(top - a + 1):
                dp = dp * v + p
                p = p * v + coeffs[a, top - a - ib]
            zu = zu * u + z
            z = z * u + p
            zv = zv * u + dp
        phi[i, j, k] = (wp.dot(d, normal) - scale * z) / wp.sqrt(1.0 + zu * zu + zv * zv)

def launch_height_field(
    phi: wp.array,
    coeffs: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    point: tuple[float, float, float],
    axes: tuple[tuple[float, float, float], ...],
    scale: float,
) -> None:
    """Fill ``phi`` with the height field ``z(u, v)`` over the plane ``(point, axes)``.

    ``axes`` holds the plane's two in-plane unit axes and its unit normal; ``coeffs`` is the
    square matrix of :meth:`warpspec.initial.HeightFit.coefficient_matrix` (float32).
    """
    wp.launch(height_field, dim=(phi.shape[0], phi.shape[1]),
              inputs=[wp.vec3(*origin), float(spacing), wp.vec3(*point), wp.vec3(*axes[0]),
                      wp.vec3(*axes[1]), wp.vec3(*axes[2]), float(scale), coeffs],
              outputs=[phi], device=phi.device)

@wp.kernel
def blend_fields(
    a: wp.array3d[float], b: wp.array3d[float], beta: float, out: wp.array3d[float]
):
    """``out = a + beta (b - a)``."""
    i, j, k = wp.tid()
    out[i, j, k] = a[i, j, k] + beta * (b[i, j, k] - a[i, j, k])

def launch_blend(a: wp.array, b: wp.array, out: wp.array, *, beta: float) -> None:
    """Write ``a + beta (b - a)`` into ``out`` (which may alias ``a`` or ``b``)."""
    wp.launch(blend_fields, dim=a.shape, inputs=[a, b, float(beta)], outputs=[out],
              device=a.device)

def launch_plane(
    phi: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    point: tuple[float, float, float],
    normal: tuple[float, float, float],
) -> None:
    """Fill ``phi`` with the signed distance to a plane (``normal`` must be unit length)."""
    wp.launch(plane_field, dim=phi.shape, inputs=[wp.vec3(*origin), float(spacing),
              wp.vec3(*point), wp.vec3(*normal)], outputs=[phi], device=phi.device)

def launch_bend(
    phi: wp.array, dist: wp.array, out: wp.array, *, spacing: float, c: float
) -> None:
    """Write ``phi - c * d * |grad phi|`` into ``out`` (a positive ``c`` moves toward phi > 0)."""
    wp.launch(bend_field, dim=phi.shape, inputs=[phi, dist, float(spacing), float(c)],
              outputs=[out], device=phi.device)
