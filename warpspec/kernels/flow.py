"""The PDE step of the paper's flow (eq. 21), dense or over the narrow band.

Conventions (docs/DESIGN.md section 3): ``phi < 0`` inside, node ``(i, j, k)`` at
``origin + h * (i, j, k)``, zero normal derivative at the boundary (indices are clamped).

The solver's iteration is one fused kernel, :func:`flow_step`, that evaluates

    phi_t = w_N |grad phi| div(n - V) + alpha kappa |grad phi|

explicitly and then applies the exact decay ``phi * exp(-w_P G dt)`` of the point term.
The extended normal field ``V`` is stored sparsely: ``owner[i, j, k]`` is the index of the ray
whose normal ``N_i`` replaces ``n`` at that node, or a value ``>= len(normals)`` where
``V = n`` (so ``n - V`` vanishes there and the normal term is exactly zero away from the
constraints). Of those, :data:`NO_OWNER` also says that no neighbour of the node is owned,
which lets the step skip the divergence there; :data:`NEIGHBOUR_OWNED` marks the unowned
neighbours of owned nodes.
"""

from __future__ import annotations

import warp as wp

from .._parallel import launch_halves
from .band import band_slot
from .stencils import central_gradient, curvature_term, unit_normal

wp.set_module_options({"enable_backward": False})

__all__ = [
    "flow_step",
    "flow_step_band",
    "launch_flow_step",
    "launch_flow_step_band",
    "NEIGHBOUR_OWNED",
    "NO_OWNER",
]

NO_OWNER = wp.constant(2**30)

NEIGHBOUR_OWNED = wp.constant(2**30 - 1)

@wp.func
def constraint_offset(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    i: int,
    j: int,
    k: int,
    inv_2h: float,
) -> wp.vec3:
    """``n - V`` at a node: zero unless a ray's normal owns the node."""
    ii = wp.clamp(i, 0, phi.shape[0] - 1)
    jj = wp.clamp(j, 0, phi.shape[1] - 1)
    kk = wp.clamp(k, 0, phi.shape[2] - 1)
    o = owner[ii, jj, kk]
    if o < 0 or o >= normals.shape[0]:
        return wp.vec3(0.0, 0.0, 0.0)
    return unit_normal(phi, ii, jj, kk, inv_2h) - normals[o]

@wp.func
def normal_divergence(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    i: int,
    j: int,
    k: int,
    inv_2h: float,
) -> float:
    """Central-difference divergence of ``n - V``: equals ``kappa - div N`` near constraints."""
    dx = (
        constraint_offset(phi, owner, normals, i + 1, j, k, inv_2h)[0]
        - constraint_offset(phi, owner, normals, i - 1, j, k, inv_2h)[0]
    )
    dy = (
        constraint_offset(phi, owner, normals, i, j + 1, k, inv_2h)[1]
        - constraint_offset(phi, owner, normals, i, j - 1, k, inv_2h)[1]
    )
    dz = (
        constraint_offset(phi, owner, normals, i, j, k + 1, inv_2h)[2]
        - constraint_offset(phi, owner, normals, i, j, k - 1, inv_2h)[2]
    )
    return (dx + dy + dz) * inv_2h

@wp.func
def advance(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    gauss: wp.array3d[float],
    i: int,
    j: int,
    k: int,
    h: float,
    dt: float,
    normal_weight: float,
    alpha: float,
    point_weight: float,
) -> float:
    """The value of one node after one step of the total-energy flow."""
    inv_2h = 0.5 / h
    rate = float(0.0)
    if alpha != 0.0:
        rate += alpha * curvature_term(phi, i, j, k, h)
    if normal_weight != 0.0 and owner[i, j, k] != NO_OWNER:  # else no neighbour is owned
        div = normal_divergence(phi, owner, normals, i, j, k, inv_2h)
        if div != 0.0:
            g = wp.length(central_gradient(phi, i, j, k, inv_2h))
            rate += normal_weight * g * div
    value = phi[i, j, k] + dt * rate
    if point_weight != 0.0:
        w = gauss[i, j, k]
        if w > 0.0:
            value *= wp.exp(-point_weight * w * dt)
    return value

@wp.kernel
def flow_step(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    gauss: wp.array3d[float],
    h: float,
    dt: float,
    normal_weight: float,
    alpha: float,
    point_weight: float,
    out: wp.array3d[float],
):
    """One explicit step of the total-energy flow (paper eq. 21), point term decayed exactly."""
    i, j, k = wp.tid()
    out[i, j, k] = advance(phi, owner, normals, gauss, i, j, k, h, dt, normal_weight, alpha,
                           point_weight)

@wp.kernel
def flow_step_band(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    gauss: wp.array3d[float],
    band: wp.array[int],
    count: wp.array[int],
    first: int,
    h: float,
    dt: float,
    normal_weight: float,
    alpha: float,
    point_weight: float,
    out: wp.array3d[float],
):
    """The flow step on the nodes of a narrow band only (``band[:count[0]]``, see build_band).

    Thread ``t`` takes slot ``first + t``.
    """
    n = band_slot(band, count, first + wp.tid(), 0,
                  wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2]))
    if n[0] < 0:
        return
    out[n[0], n[1], n[2]] = advance(phi, owner, normals, gauss, n[0], n[1], n[2], h, dt,
                                    normal_weight, alpha, point_weight)

def launch_flow_step(
    phi: wp.array,
    owner: wp.array,
    normals: wp.array,
    gauss: wp.array,
    out: wp.array,
    *,
    spacing: float,
    dt: float,
    normal_weight: float = 1.0,
    alpha: float = 0.0,
    point_weight: float = 0.0,
) -> None:
    """Advance ``phi`` by one step of the total-energy flow into ``out``.

    Args:
        phi: Level set (float32, 3-D).
        owner: Per-node index into ``normals`` where a constraint owns the node, else
            ``>= len(normals)`` (or negative).
        normals: Constraint normals ``N_i``.
        gauss: Point-attraction field ``G``.
        out: Destination, same shape as ``phi`` (must not alias it).
        spacing: Grid spacing ``h``.
        dt: Time step.
        normal_weight: Weight of the normal term (0 switches it off).
        alpha: Weight of the smoothness (mean curvature) term.
        point_weight: ``w_P``, the rate of the point term's exact decay.
    """
    wp.launch(
        flow_step,
        dim=phi.shape,
        inputs=[phi, owner, normals, gauss, float(spacing), float(dt), float(normal_weight),
                float(alpha), float(point_weight)],
        outputs=[out],
        device=phi.device,
    )

def launch_flow_step_band(
    phi: wp.array,
    owner: wp.array,
    normals: wp.array,
    gauss: wp.array,
    band: wp.array,
    count: wp.array,
    out: wp.array,
    *,
    size: int,
    spacing: float,
    dt: float,
    normal_weight: float = 1.0,
    alpha: float = 0.0,
    point_weight: float = 0.0,
) -> None:
    """Advance the nodes of a narrow band by one step of the flow into ``out``.

    Args:
        phi: Level set.
        owner: Constraint owner per node (see :func:`launch_flow_step`).
        normals: Constraint normals.
        gauss: Point-attraction field.
        band: The band's nodes, as :func:`launch_build_band` encodes them.
        count: One int, the number of valid entries of ``band``.
        out: Destination; nodes outside the band are not written.
        size: Threads to launch: the band's size when known on the host (CPU, where two
            cores share it), else the capacity of ``band`` (threads past ``count`` return at
            once; graph-capturable).
        spacing: Grid spacing ``h``.
        dt: Time step.
        normal_weight: Weight of the normal term.
        alpha: Weight of the smoothness term.
        point_weight: ``w_P``.
    """
    if size == 0:
        return
    def launch(first: int, threads: int, _half: int) -> None:
        wp.launch(
            flow_step_band,
            dim=threads,
            inputs=[phi, owner, normals, gauss, band, count, first, float(spacing), float(dt),
                    float(normal_weight), float(alpha), float(point_weight)],
            outputs=[out],
            device=phi.device,
        )

    launch_halves(launch, size, phi.device)
