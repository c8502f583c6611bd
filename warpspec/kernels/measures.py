"""Reductions behind the per-iteration measures, into named slots of a float64 array.

The slots are ``wp.constant`` values shared by the kernels and the host
(:data:`MEASURE_SLOTS`); surface integrals use the smeared delta of width ``1.5 h``.
"""

from __future__ import annotations

import warp as wp

from .band import band_slot
from .sampling import trilinear, trilinear_gradient
from .stencils import central_gradient, unit_normal

wp.set_module_options({"enable_backward": False})

__all__ = [
    "launch_measures",
    "MEASURE_SLOTS",
    "NUM_SLOTS",
]

SLOT_NORMAL_ERROR = wp.constant(0)
"""Sum of ``1 - N_i . n(x_i)`` over the active rays."""
SLOT_ACTIVE = wp.constant(1)
"""Rays that meet the zero set."""
SLOT_MISSES = wp.constant(2)
"""Rays that miss it."""
SLOT_POINT_ABS = wp.constant(3)
"""Sum of ``|phi(y)|`` over the point constraints."""
SLOT_ENERGY_NORMAL = wp.constant(4)
"""``E_N``, the normal energy over the zero set."""
SLOT_ENERGY_SMOOTH = wp.constant(5)
"""The surface area."""
SLOT_NONFINITE = wp.constant(6)
"""Nodes of non-finite value."""

MEASURE_SLOTS = {
    "normal_error_sum": SLOT_NORMAL_ERROR,
    "active": SLOT_ACTIVE,
    "misses": SLOT_MISSES,
    "point_abs_sum": SLOT_POINT_ABS,
    "energy_normal": SLOT_ENERGY_NORMAL,
    "energy_smooth": SLOT_ENERGY_SMOOTH,
    "nonfinite": SLOT_NONFINITE,
}
"""Slots of the float64 accumulator by name, the same constants the kernels write."""
NUM_SLOTS = len(MEASURE_SLOTS)


@wp.kernel
def measure_rays(
    phi: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    hits: wp.array[wp.vec3],
    active: wp.array[int],
    normals: wp.array[wp.vec3],
    sums: wp.array[wp.float64],
):
    """Accumulate ``1 - N_i . n(x_i)`` over active rays, their count and the misses."""
    r = wp.tid()
    if active[r] == 0:
        wp.atomic_add(sums, SLOT_MISSES, wp.float64(1.0))
        return
    g = trilinear_gradient(phi, origin, h, hits[r])
    n = wp.normalize(g)
    wp.atomic_add(sums, SLOT_NORMAL_ERROR, wp.float64(1.0 - wp.dot(normals[r], n)))
    wp.atomic_add(sums, SLOT_ACTIVE, wp.float64(1.0))

@wp.kernel
def measure_points(
    phi: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    points: wp.array[wp.vec3],
    sums: wp.array[wp.float64],
):
    """Accumulate ``|phi(y)|`` over the point constraints."""
    p = wp.tid()
    wp.atomic_add(sums, SLOT_POINT_ABS, wp.float64(wp.abs(trilinear(phi, origin, h, points[p]))))

@wp.func
def measure_node(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    i: int,
    j: int,
    k: int,
    h: float,
    sums: wp.array[wp.float64],
):
    """One node's share of ``E_N`` and the surface area, or of the non-finite count.

    Surface integrals use the smeared delta ``(1 + cos(pi phi / w)) / (2 w)``, ``w = 1.5 h``.
    """
    c = phi[i, j, k]
    if not wp.isfinite(c):
        wp.atomic_add(sums, SLOT_NONFINITE, wp.float64(1.0))
        return
    width = 1.5 * h
    if wp.abs(c) >= width:
        return
    delta = (1.0 + wp.cos(wp.pi * c / width)) / (2.0 * width)
    grad = wp.length(central_gradient(phi, i, j, k, 0.5 / h))
    ds = delta * grad * h * h * h
    wp.atomic_add(sums, SLOT_ENERGY_SMOOTH, wp.float64(ds))
    o = owner[i, j, k]
    if o >= 0 and o < normals.shape[0]:
        n = unit_normal(phi, i, j, k, 0.5 / h)
        wp.atomic_add(sums, SLOT_ENERGY_NORMAL, wp.float64((1.0 - wp.dot(normals[o], n)) * ds))

@wp.kernel
def measure_grid(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    h: float,
    sums: wp.array[wp.float64],
):
    """Grid integrals over every node: ``E_N``, the surface area, non-finite values."""
    i, j, k = wp.tid()
    measure_node(phi, owner, normals, i, j, k, h, sums)

@wp.kernel
def measure_band(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    band: wp.array[int],
    count: wp.array[int],
    h: float,
    sums: wp.array[wp.float64],
):
    """Grid integrals over the nodes of a narrow band (the only ones that change)."""
    n = band_slot(band, count, wp.tid(), 0, wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2]))
    if n[0] < 0:
        return
    measure_node(phi, owner, normals, n[0], n[1], n[2], h, sums)

def launch_measures(
    phi: wp.array,
    owner: wp.array,
    normals: wp.array,
    hits: wp.array,
    active: wp.array,
    points: wp.array,
    sums: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    band: wp.array | None = None,
    count: wp.array | None = None,
    size: int = 0,
) -> None:
    """Zero ``sums`` (float64, :data:`MEASURE_SLOTS`) and accumulate every measure into it.

    With ``band`` (and its ``count`` and launch ``size``), the grid integrals visit only the
    band's nodes, which hold the whole zero set and every node that changes.
    """
    sums.zero_()
    o = wp.vec3(*origin)
    h = float(spacing)
    if hits.shape[0] > 0:
        wp.launch(measure_rays, dim=hits.shape[0], inputs=[phi, o, h, hits, active, normals],
                  outputs=[sums], device=phi.device)
    if points.shape[0] > 0:
        wp.launch(measure_points, dim=points.shape[0], inputs=[phi, o, h, points],
                  outputs=[sums], device=phi.device)
    if band is None:
        wp.launch(measure_grid, dim=phi.shape, inputs=[phi, owner, normals, h],
                  outputs=[sums], device=phi.device)
    elif size > 0:
        wp.launch(measure_band, dim=size, inputs=[phi, owner, normals, band, count, h],
                  outputs=[sums], device=phi.device)
