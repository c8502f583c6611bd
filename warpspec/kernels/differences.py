"""Finite differences on the level set: gradients, curvature and the flows built from them.

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

wp.set_module_options({"enable_backward": False})

__all__ = [
    "NEIGHBOUR_OWNED",
    "NO_OWNER",
    "central_gradient",
    "curvature_term",
    "flow_step",
    "launch_central_gradient",
    "launch_curvature_term",
    "launch_build_band",
    "launch_flow_step",
    "launch_flow_step_band",
    "launch_upwind_gradient_norm",
    "upwind_gradient_norm",
]

TINY = 1.0e-12
NO_OWNER = wp.constant(2**30)
NEIGHBOUR_OWNED = wp.constant(2**30 - 1)


@wp.func
def at(phi: wp.array3d[float], i: int, j: int, k: int) -> float:
    """Value at a node, with indices clamped to the grid (zero normal derivative)."""
    ii = wp.clamp(i, 0, phi.shape[0] - 1)
    jj = wp.clamp(j, 0, phi.shape[1] - 1)
    kk = wp.clamp(k, 0, phi.shape[2] - 1)
    return phi[ii, jj, kk]


@wp.func
def central_gradient(phi: wp.array3d[float], i: int, j: int, k: int, inv_2h: float) -> wp.vec3:
    """Second-order central-difference gradient at a node."""
    ip = wp.min(i + 1, phi.shape[0] - 1)
    im = wp.max(i - 1, 0)
    jp = wp.min(j + 1, phi.shape[1] - 1)
    jm = wp.max(j - 1, 0)
    kp = wp.min(k + 1, phi.shape[2] - 1)
    km = wp.max(k - 1, 0)
    return wp.vec3(
        (phi[ip, j, k] - phi[im, j, k]) * inv_2h,
        (phi[i, jp, k] - phi[i, jm, k]) * inv_2h,
        (phi[i, j, kp] - phi[i, j, km]) * inv_2h,
    )


@wp.func
def unit_normal(phi: wp.array3d[float], i: int, j: int, k: int, inv_2h: float) -> wp.vec3:
    """Outward unit normal ``grad phi / |grad phi|`` from central differences (zero if flat)."""
    g = central_gradient(phi, i, j, k, inv_2h)
    length = wp.length(g)
    if length < TINY:
        return wp.vec3(0.0, 0.0, 0.0)
    return g / length


@wp.func
def curvature_term(phi: wp.array3d[float], i: int, j: int, k: int, h: float) -> float:
    """``kappa |grad phi|`` with the usual central-difference mean curvature, ``|kappa| <= 1/h``.

    The neighbours' indices are clamped once per axis (a clamp per read costs about 30% of
    the term on the CPU); clamping per axis is what :func:`at` does.
    """
    inv_2h = 0.5 / h
    inv_h2 = 1.0 / (h * h)
    inv_4h2 = 0.25 * inv_h2
    ip = wp.min(i + 1, phi.shape[0] - 1)
    im = wp.max(i - 1, 0)
    jp = wp.min(j + 1, phi.shape[1] - 1)
    jm = wp.max(j - 1, 0)
    kp = wp.min(k + 1, phi.shape[2] - 1)
    km = wp.max(k - 1, 0)
    c = phi[i, j, k]
    xp = phi[ip, j, k]
    xm = phi[im, j, k]
    yp = phi[i, jp, k]
    ym = phi[i, jm, k]
    zp = phi[i, j, kp]
    zm = phi[i, j, km]
    px = (xp - xm) * inv_2h
    py = (yp - ym) * inv_2h
    pz = (zp - zm) * inv_2h
    pxx = (xp - 2.0 * c + xm) * inv_h2
    pyy = (yp - 2.0 * c + ym) * inv_h2
    pzz = (zp - 2.0 * c + zm) * inv_h2
    pxy = (phi[ip, jp, k] - phi[ip, jm, k] - phi[im, jp, k] + phi[im, jm, k]) * inv_4h2
    pxz = (phi[ip, j, kp] - phi[ip, j, km] - phi[im, j, kp] + phi[im, j, km]) * inv_4h2
    pyz = (phi[i, jp, kp] - phi[i, jp, km] - phi[i, jm, kp] + phi[i, jm, km]) * inv_4h2
    g2 = px * px + py * py + pz * pz
    if g2 < TINY:
        return 0.0
    num = (
        pxx * (py * py + pz * pz)
        + pyy * (px * px + pz * pz)
        + pzz * (px * px + py * py)
        - 2.0 * (px * py * pxy + px * pz * pxz + py * pz * pyz)
    )
    g = wp.sqrt(g2)
    kappa = wp.clamp(num / (g2 * g), -1.0 / h, 1.0 / h)
    return kappa * g


@wp.func
def minmod(a: float, b: float) -> float:
    """The smaller in magnitude of two numbers of one sign, else zero."""
    if a * b <= 0.0:
        return 0.0
    if wp.abs(a) < wp.abs(b):
        return a
    return b


@wp.func
def one_sided(phi: wp.array3d[float], i: int, j: int, k: int, axis: int, inv_h: float) -> wp.vec2:
    """Second-order ENO one-sided differences ``(D-, D+)`` along one axis."""
    di = wp.where(axis == 0, 1, 0)
    dj = wp.where(axis == 1, 1, 0)
    dk = wp.where(axis == 2, 1, 0)
    m2 = at(phi, i - 2 * di, j - 2 * dj, k - 2 * dk)
    m1 = at(phi, i - di, j - dj, k - dk)
    c = phi[i, j, k]
    p1 = at(phi, i + di, j + dj, k + dk)
    p2 = at(phi, i + 2 * di, j + 2 * dj, k + 2 * dk)
    dd_m = m2 - 2.0 * m1 + c
    dd_c = m1 - 2.0 * c + p1
    dd_p = c - 2.0 * p1 + p2
    minus = (c - m1 + 0.5 * minmod(dd_m, dd_c)) * inv_h
    plus = (p1 - c - 0.5 * minmod(dd_c, dd_p)) * inv_h
    return wp.vec2(minus, plus)


@wp.func
def upwind_gradient_norm(
    phi: wp.array3d[float], i: int, j: int, k: int, inv_h: float, speed: float
) -> float:
    """Godunov upwind ``|grad phi|`` for a front moving with normal speed of sign ``speed``.

    The one-sided differences are second-order ENO.
    """
    s = float(0.0)
    for axis in range(3):
        d = one_sided(phi, i, j, k, axis, inv_h)
        if speed >= 0.0:
            a = wp.max(d[0], 0.0)
            b = wp.min(d[1], 0.0)
        else:
            a = wp.min(d[0], 0.0)
            b = wp.max(d[1], 0.0)
        s += wp.max(a * a, b * b)
    return wp.sqrt(s)


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


@wp.func
def unflatten(t: int, shape: wp.vec3i) -> wp.vec3i:
    """Node ``(i, j, k)`` of the linear index ``t`` of a C-ordered 3-D array."""
    plane = shape[1] * shape[2]
    return wp.vec3i(t // plane, (t // shape[2]) % shape[1], t % shape[2])


@wp.func
def packable(shape: wp.vec3i) -> bool:
    """Whether a node of ``shape`` fits in one int as ``i << 20 | j << 10 | k``."""
    return shape[0] <= 2048 and shape[1] <= 1024 and shape[2] <= 1024


@wp.func
def band_node(code: int, shape: wp.vec3i) -> wp.vec3i:
    """Node ``(i, j, k)`` of a narrow band's entry (see :func:`build_band`).

    Grids up to 2048 x 1024 x 1024 nodes store the node bit-packed, which decodes in a few
    shifts; larger ones store the linear index, which costs three integer divisions (about
    16 ns more a node on the CPU, on every pass over the band).
    """
    if packable(shape):
        return wp.vec3i(code >> 20, (code >> 10) & 1023, code & 1023)
    return unflatten(code, shape)


@wp.func
def band_slot(band: wp.array[int], count: wp.array[int], s: int, reverse: int,
              shape: wp.vec3i) -> wp.vec3i:
    """Node of slot ``s`` of a band list (from its end when ``reverse``), or -1s past the list."""
    n = count[0]
    if s >= n:
        return wp.vec3i(-1, -1, -1)
    return band_node(band[wp.where(reverse == 1, n - 1 - s, s)], shape)


@wp.kernel
def flow_step_band(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    gauss: wp.array3d[float],
    band: wp.array[int],
    count: wp.array[int],
    h: float,
    dt: float,
    normal_weight: float,
    alpha: float,
    point_weight: float,
    out: wp.array3d[float],
):
    """The flow step on the nodes of a narrow band only (``band[:count[0]]``, see build_band)."""
    n = band_slot(band, count, wp.tid(), 0, wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2]))
    if n[0] < 0:
        return
    out[n[0], n[1], n[2]] = advance(phi, owner, normals, gauss, n[0], n[1], n[2], h, dt,
                                    normal_weight, alpha, point_weight)


@wp.kernel
def build_band(
    phi: wp.array[float],
    shape: wp.vec3i,
    width: float,
    band: wp.array[int],
    count: wp.array[int],
):
    """Append every node with ``|phi| <= width`` to ``band`` (``phi`` flattened, C order).

    An entry is the node bit-packed as ``i << 20 | j << 10 | k`` where the grid allows it
    (:func:`packable`), else its linear index; :func:`band_node` decodes either. Both orders
    agree with C order. The order of the list is not significant (on the CPU it comes out in
    index order).
    """
    t = wp.tid()
    if wp.abs(phi[t]) <= width:
        code = t
        if packable(shape):
            n = unflatten(t, shape)
            code = (n[0] << 20) | (n[1] << 10) | n[2]
        slot = wp.atomic_add(count, 0, 1)
        band[slot] = code


@wp.kernel
def central_gradient_field(phi: wp.array3d[float], h: float, out: wp.array3d[wp.vec3]):
    """Central-difference gradient at every node."""
    i, j, k = wp.tid()
    out[i, j, k] = central_gradient(phi, i, j, k, 0.5 / h)


@wp.kernel
def upwind_gradient_norm_field(
    phi: wp.array3d[float], h: float, speed: float, out: wp.array3d[float]
):
    """Godunov upwind ``|grad phi|`` at every node for a normal speed of sign ``speed``."""
    i, j, k = wp.tid()
    out[i, j, k] = upwind_gradient_norm(phi, i, j, k, 1.0 / h, speed)


@wp.kernel
def curvature_term_field(phi: wp.array3d[float], h: float, out: wp.array3d[float]):
    """``kappa |grad phi|`` at every node."""
    i, j, k = wp.tid()
    out[i, j, k] = curvature_term(phi, i, j, k, h)


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
        size: Threads to launch: the band's size when known on the host (CPU), else the
            capacity of ``band`` (threads past ``count`` return at once; graph-capturable).
        spacing: Grid spacing ``h``.
        dt: Time step.
        normal_weight: Weight of the normal term.
        alpha: Weight of the smoothness term.
        point_weight: ``w_P``.
    """
    if size == 0:
        return
    wp.launch(
        flow_step_band,
        dim=size,
        inputs=[phi, owner, normals, gauss, band, count, float(spacing), float(dt),
                float(normal_weight), float(alpha), float(point_weight)],
        outputs=[out],
        device=phi.device,
    )


def launch_build_band(phi: wp.array, band: wp.array, count: wp.array, *, width: float) -> None:
    """Collect the nodes with ``|phi| <= width`` into ``band``; their number into ``count``."""
    count.zero_()
    # A 1-D launch over the flattened array: on the CPU a 3-D launch costs ~18 ns a thread.
    flat = phi.flatten()
    wp.launch(build_band, dim=flat.shape[0], inputs=[flat, wp.vec3i(*phi.shape), float(width)],
              outputs=[band, count], device=phi.device)


def launch_central_gradient(phi: wp.array, out: wp.array, *, spacing: float) -> None:
    """Write the central-difference gradient of ``phi`` (vec3 per node) into ``out``."""
    wp.launch(central_gradient_field, dim=phi.shape, inputs=[phi, float(spacing)],
              outputs=[out], device=phi.device)


def launch_upwind_gradient_norm(
    phi: wp.array, out: wp.array, *, spacing: float, speed: float = 1.0
) -> None:
    """Write the Godunov upwind gradient magnitude of ``phi`` into ``out``."""
    wp.launch(upwind_gradient_norm_field, dim=phi.shape, inputs=[phi, float(spacing),
              float(speed)], outputs=[out], device=phi.device)


def launch_curvature_term(phi: wp.array, out: wp.array, *, spacing: float) -> None:
    """Write ``kappa |grad phi|`` (curvature capped at ``1/h``) into ``out``."""
    wp.launch(curvature_term_field, dim=phi.shape, inputs=[phi, float(spacing)],
              outputs=[out], device=phi.device)
