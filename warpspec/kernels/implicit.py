"""Kernels of the implicit start: a smooth function on the grid fitted to points and normals.

The fit minimises, over the nodal values ``f`` of a grid (trilinear in each cell),

    sum_s w_s |grad f(x_s) - N_s|^2  +  mu sum_y f(y)^2 / h^2
        +  lam * sum_nodes (f_xx^2 + f_yy^2 + f_zz^2 + 2 f_xy^2 + 2 f_xz^2 + 2 f_yz^2) h^2
        +  eps * sum_nodes (f - f_prev)^2 / h^2

(the Hessian energy of Smooth Signed Distance reconstruction, Calakli and Taubin 2011, with
normals at samples ``x_s`` taken near where the specular rays meet the current surface; the
second differences are ``h^2`` times the derivatives, so every term is free of units). The
normal equations ``A f = b`` are solved by Jacobi-preconditioned conjugate gradients whose
scalars stay on the device: an iteration is a fixed sequence of launches with no host
synchronisation, ready for graph capture.

Every kernel is written for any thread order: the data terms scatter with atomic additions,
and the reductions add per-thread partial sums (in float64) atomically.
"""

from __future__ import annotations

import warp as wp

from .rays import bisect_crossing, grid_span, reflection_normal
from .sampling import cell_corner, corner_weight, grid_coordinate, trilinear

wp.set_module_options({"enable_backward": False})

__all__ = [
    "ANCHOR_CROSSING",
    "ANCHOR_NEAREST",
    "ANCHOR_NONE",
    "CG_SLOTS",
    "REDUCE_CHUNK",
]

ANCHOR_NONE = wp.constant(0)
"""The ray does not enter the grid."""
ANCHOR_CROSSING = wp.constant(1)
"""The ray crosses the zero set from outside: the anchor is the first crossing."""
ANCHOR_NEAREST = wp.constant(2)
"""The ray misses the zero set: the anchor is where ``|f|`` is smallest along it."""

REDUCE_CHUNK = 256
"""Nodes summed by one thread of a reduction before its atomic addition."""

# Slots of the conjugate-gradient scalars (float64): r.z (current), p.Ap, r.z (next), r.r.
CG_SLOTS = {"rz": 0, "pap": 1, "rz_next": 2, "rr": 3}
_RZ = wp.constant(0)
_PAP = wp.constant(1)
_RZ_NEXT = wp.constant(2)
_RR = wp.constant(3)


@wp.func
def corner_gradient(f: wp.vec3, c: int, inv_h: float) -> wp.vec3:
    """Gradient (world units) of the trilinear weight of corner ``c`` at fractions ``f``."""
    bx = (c & 1) == 1
    by = ((c >> 1) & 1) == 1
    bz = ((c >> 2) & 1) == 1
    wx = wp.where(bx, f[0], 1.0 - f[0])
    wy = wp.where(by, f[1], 1.0 - f[1])
    wz = wp.where(bz, f[2], 1.0 - f[2])
    dx = wp.where(bx, 1.0, -1.0)
    dy = wp.where(by, 1.0, -1.0)
    dz = wp.where(bz, 1.0, -1.0)
    return wp.vec3(dx * wy * wz, wx * dy * wz, wx * wy * dz) * inv_h


@wp.func
def corner_node(n: wp.vec3i, c: int) -> wp.vec3i:
    """Node of corner ``c`` (bits: x, y, z) of the cell whose lowest node is ``n``."""
    return wp.vec3i(n[0] + (c & 1), n[1] + ((c >> 1) & 1), n[2] + ((c >> 2) & 1))


@wp.func
def cell_of(field: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> wp.vec3i:
    """Lowest node of the cell holding the world point ``x`` (clamped to the grid)."""
    return cell_corner(field, grid_coordinate(field, origin, h, x))


@wp.func
def cell_fraction(field: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3,
                  n: wp.vec3i) -> wp.vec3:
    """Fractions of ``x`` inside the cell whose lowest node is ``n``."""
    q = grid_coordinate(field, origin, h, x)
    return q - wp.vec3(float(n[0]), float(n[1]), float(n[2]))


@wp.func
def cell_gradient(field: wp.array3d[float], n: wp.vec3i, fr: wp.vec3, inv_h: float) -> wp.vec3:
    """Gradient of the trilinear interpolant inside one cell."""
    g = wp.vec3(0.0, 0.0, 0.0)
    for c in range(8):
        q = corner_node(n, c)
        g += field[q[0], q[1], q[2]] * corner_gradient(fr, c, inv_h)
    return g


@wp.func
def second_difference(f: wp.array3d[float], i: int, j: int, k: int, axis: int) -> float:
    """``f[p-e] - 2 f[p] + f[p+e]`` along ``axis``; 0 where the stencil leaves the grid."""
    e = wp.vec3i(0, 0, 0)
    e[axis] = 1
    p = wp.vec3i(i, j, k)
    if p[axis] < 1 or p[axis] > f.shape[axis] - 2:
        return 0.0
    return f[i - e[0], j - e[1], k - e[2]] - 2.0 * f[i, j, k] + f[i + e[0], j + e[1], k + e[2]]


@wp.func
def mixed_difference(f: wp.array3d[float], i: int, j: int, k: int, a: int, b: int) -> float:
    """Quarter of the cross difference along axes ``a`` and ``b``; 0 off the interior."""
    p = wp.vec3i(i, j, k)
    if p[a] < 1 or p[a] > f.shape[a] - 2 or p[b] < 1 or p[b] > f.shape[b] - 2:
        return 0.0
    ea = wp.vec3i(0, 0, 0)
    eb = wp.vec3i(0, 0, 0)
    ea[a] = 1
    eb[b] = 1
    pp = p + ea + eb
    pm = p + ea - eb
    mp = p - ea + eb
    mm = p - ea - eb
    return 0.25 * (f[pp[0], pp[1], pp[2]] - f[pm[0], pm[1], pm[2]]
                   - f[mp[0], mp[1], mp[2]] + f[mm[0], mm[1], mm[2]])


@wp.kernel
def hessian_terms(i0: int, f: wp.array3d[float], diag: wp.array3d[wp.vec3],
                  mixed: wp.array3d[wp.vec3]):
    """Second differences of ``f`` at every node: ``(xx, yy, zz)`` and ``(xy, xz, yz)``.

    Thread ``(i, j, k)`` takes node ``(i0 + i, j, k)`` (a launch may cover a slab).
    """
    i, j, k = wp.tid()
    i = i + i0
    diag[i, j, k] = wp.vec3(second_difference(f, i, j, k, 0), second_difference(f, i, j, k, 1),
                            second_difference(f, i, j, k, 2))
    mixed[i, j, k] = wp.vec3(mixed_difference(f, i, j, k, 0, 1),
                             mixed_difference(f, i, j, k, 0, 2),
                             mixed_difference(f, i, j, k, 1, 2))


@wp.func
def _component_at(diag: wp.array3d[wp.vec3], p: wp.vec3i, axis: int) -> float:
    if p[0] < 0 or p[1] < 0 or p[2] < 0:
        return 0.0
    if p[0] >= diag.shape[0] or p[1] >= diag.shape[1] or p[2] >= diag.shape[2]:
        return 0.0
    return diag[p[0], p[1], p[2]][axis]


@wp.kernel
def hessian_adjoint(
    i0: int,
    diag: wp.array3d[wp.vec3],
    mixed: wp.array3d[wp.vec3],
    f: wp.array3d[float],
    lam: float,
    eps: float,
    out: wp.array3d[float],
):
    """``out = lam * D^T W D f + eps * f``: the smoothness and the proximity terms.

    ``D`` stacks the six second differences, ``W`` weighs the mixed ones twice (the Frobenius
    norm of the Hessian counts ``f_xy`` and ``f_yx``). Writes every node of ``out`` (thread
    ``(i, j, k)`` node ``(i0 + i, j, k)``).
    """
    i, j, k = wp.tid()
    i = i + i0
    q = wp.vec3i(i, j, k)
    s = float(0.0)
    for axis in range(3):
        e = wp.vec3i(0, 0, 0)
        e[axis] = 1
        s += (_component_at(diag, q - e, axis) - 2.0 * _component_at(diag, q, axis)
              + _component_at(diag, q + e, axis))
    for m in range(3):
        a = wp.where(m == 2, 1, 0)
        b = wp.where(m == 0, 1, 2)
        ea = wp.vec3i(0, 0, 0)
        eb = wp.vec3i(0, 0, 0)
        ea[a] = 1
        eb[b] = 1
        # adjoint of the quarter cross difference: the same stencil, read at q - (+-ea +-eb)
        t = (_component_at(mixed, q - ea - eb, m) - _component_at(mixed, q - ea + eb, m)
             - _component_at(mixed, q + ea - eb, m) + _component_at(mixed, q + ea + eb, m))
        s += 2.0 * 0.25 * t
    out[i, j, k] = lam * s + eps * f[i, j, k]


@wp.func
def _valid_second(shape: wp.vec3i, p: wp.vec3i, c: int) -> bool:
    """Whether the Hessian component ``c`` (0-2: xx, yy, zz; 3-5: xy, xz, yz) exists at ``p``."""
    if p[0] < 0 or p[1] < 0 or p[2] < 0:
        return False
    if p[0] >= shape[0] or p[1] >= shape[1] or p[2] >= shape[2]:
        return False
    a = c
    b = c
    if c >= 3:
        a = wp.where(c == 5, 1, 0)
        b = wp.where(c == 3, 1, 2)
    return p[a] >= 1 and p[a] <= shape[a] - 2 and p[b] >= 1 and p[b] <= shape[b] - 2


@wp.func
def _second_at(diag: wp.array3d[wp.vec3], mixed: wp.array3d[wp.vec3], p: wp.vec3i,
               c: int) -> float:
    if c < 3:
        return diag[p[0], p[1], p[2]][c]
    return mixed[p[0], p[1], p[2]][c - 3]


@wp.kernel
def third_terms(
    i0: int,
    diag: wp.array3d[wp.vec3],
    mixed: wp.array3d[wp.vec3],
    second_weight: float,
    third_weight: float,
    out_diag: wp.array3d[wp.vec3],
    out_mixed: wp.array3d[wp.vec3],
):
    """``out = second_weight H + third_weight G^T G H`` for the Hessian components ``H``.

    ``G`` takes the first differences of each component between neighbouring nodes where it
    exists at both, so ``|G H|^2`` is the discrete ``|D^3 f|^2`` (with the mixed components
    counted twice by :func:`hessian_adjoint`'s weights). Feeding ``out`` to
    :func:`hessian_adjoint` gives ``D^T W (second_weight + third_weight G^T G) D f``: the
    Hessian energy and the third-order energy in one pass. Thread ``(i, j, k)`` writes node
    ``(i0 + i, j, k)``.
    """
    i, j, k = wp.tid()
    i = i + i0
    q = wp.vec3i(i, j, k)
    shape = wp.vec3i(diag.shape[0], diag.shape[1], diag.shape[2])
    od = wp.vec3(0.0, 0.0, 0.0)
    om = wp.vec3(0.0, 0.0, 0.0)
    for c in range(6):
        v = float(0.0)
        if _valid_second(shape, q, c):
            here = _second_at(diag, mixed, q, c)
            s = float(0.0)
            for axis in range(3):
                e = wp.vec3i(0, 0, 0)
                e[axis] = 1
                if _valid_second(shape, q - e, c):
                    s += here - _second_at(diag, mixed, q - e, c)
                if _valid_second(shape, q + e, c):
                    s += here - _second_at(diag, mixed, q + e, c)
            v = second_weight * here + third_weight * s
        if c < 3:
            od[c] = v
        else:
            om[c - 3] = v
    out_diag[i, j, k] = od
    out_mixed[i, j, k] = om


@wp.func
def _count_second(shape: wp.vec3i, p: wp.vec3i, axis: int) -> float:
    """``sum c^2`` over the valid second-difference stencils along ``axis`` that hold ``p``."""
    n = shape[axis]
    s = float(0.0)
    if p[axis] - 1 >= 1 and p[axis] - 1 <= n - 2:
        s += 1.0
    if p[axis] >= 1 and p[axis] <= n - 2:
        s += 4.0
    if p[axis] + 1 >= 1 and p[axis] + 1 <= n - 2:
        s += 1.0
    return s


@wp.func
def _interior(shape: wp.vec3i, v: int, axis: int) -> float:
    return wp.where(v >= 1 and v <= shape[axis] - 2, 1.0, 0.0)


@wp.kernel
def hessian_diagonal(shape: wp.vec3i, lam: float, eps: float, out: wp.array3d[float]):
    """Diagonal of ``lam * D^T W D + eps * I`` (the Jacobi preconditioner's smooth part)."""
    i, j, k = wp.tid()
    p = wp.vec3i(i, j, k)
    s = _count_second(shape, p, 0) + _count_second(shape, p, 1) + _count_second(shape, p, 2)
    for m in range(3):
        a = wp.where(m == 2, 1, 0)
        b = wp.where(m == 0, 1, 2)
        # node p is a corner of the cross stencils centred at p +- e_a +- e_b
        na = _interior(shape, p[a] - 1, a) + _interior(shape, p[a] + 1, a)
        nb = _interior(shape, p[b] - 1, b) + _interior(shape, p[b] + 1, b)
        s += 2.0 * 0.0625 * na * nb
    out[i, j, k] = lam * s + eps


@wp.kernel
def gradient_apply(
    f: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    xs: wp.array[wp.vec3],
    ws: wp.array[float],
    out: wp.array3d[float],
):
    """``out += G^T W G f`` for the gradient samples (atomic scatter)."""
    s = wp.tid()
    w = ws[s]
    if w == 0.0:
        return
    n = cell_of(f, origin, h, xs[s])
    fr = cell_fraction(f, origin, h, xs[s], n)
    inv_h = 1.0 / h
    g = cell_gradient(f, n, fr, inv_h)
    for c in range(8):
        q = corner_node(n, c)
        wp.atomic_add(out, q[0], q[1], q[2], w * wp.dot(corner_gradient(fr, c, inv_h), g))


@wp.kernel
def gradient_rhs(
    field: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    xs: wp.array[wp.vec3],
    ws: wp.array[float],
    normals: wp.array[wp.vec3],
    rhs: wp.array3d[float],
    diag: wp.array3d[float],
):
    """``rhs += G^T W N`` and ``diag += diag(G^T W G)`` for the gradient samples."""
    s = wp.tid()
    w = ws[s]
    if w == 0.0:
        return
    n = cell_of(field, origin, h, xs[s])
    fr = cell_fraction(field, origin, h, xs[s], n)
    inv_h = 1.0 / h
    for c in range(8):
        gc = corner_gradient(fr, c, inv_h)
        q = corner_node(n, c)
        wp.atomic_add(rhs, q[0], q[1], q[2], w * wp.dot(gc, normals[s]))
        wp.atomic_add(diag, q[0], q[1], q[2], w * wp.dot(gc, gc))


@wp.kernel
def value_apply(
    f: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    ys: wp.array[wp.vec3],
    ws: wp.array[float],
    out: wp.array3d[float],
):
    """``out += P^T W P f`` for the value samples (the point constraints, ``f(y) = 0``)."""
    s = wp.tid()
    w = ws[s]
    if w == 0.0:
        return
    n = cell_of(f, origin, h, ys[s])
    fr = cell_fraction(f, origin, h, ys[s], n)
    v = trilinear(f, origin, h, ys[s])
    for c in range(8):
        q = corner_node(n, c)
        wp.atomic_add(out, q[0], q[1], q[2], w * corner_weight(fr, c) * v)


@wp.kernel
def value_diagonal(
    field: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    ys: wp.array[wp.vec3],
    ws: wp.array[float],
    diag: wp.array3d[float],
):
    """``diag += diag(P^T W P)`` for the value samples."""
    s = wp.tid()
    n = cell_of(field, origin, h, ys[s])
    fr = cell_fraction(field, origin, h, ys[s], n)
    for c in range(8):
        cw = corner_weight(fr, c)
        q = corner_node(n, c)
        wp.atomic_add(diag, q[0], q[1], q[2], ws[s] * cw * cw)


@wp.kernel
def proximity_rhs(prev: wp.array3d[float], eps: float, prior: wp.array3d[float],
                  rhs: wp.array3d[float]):
    """``rhs = eps * prev + prior``: the proximity term's and the prior's share (written)."""
    i, j, k = wp.tid()
    rhs[i, j, k] = eps * prev[i, j, k] + prior[i, j, k]


# -- conjugate gradients on flat views ------------------------------------------------------


@wp.kernel
def cg_start(
    b: wp.array[float],
    ax: wp.array[float],
    inv_diag: wp.array[float],
    count: int,
    r: wp.array[float],
    p: wp.array[float],
    scalars: wp.array[wp.float64],
):
    """``r = b - A x``, ``p = M^-1 r``; adds ``r.M^-1 r`` and ``r.r`` (slots rz, rr)."""
    t = wp.tid()
    rz = wp.float64(0.0)
    rr = wp.float64(0.0)
    for u in range(REDUCE_CHUNK):
        s = t * REDUCE_CHUNK + u
        if s < count:
            ri = b[s] - ax[s]
            zi = ri * inv_diag[s]
            r[s] = ri
            p[s] = zi
            rz += wp.float64(ri * zi)
            rr += wp.float64(ri * ri)
    wp.atomic_add(scalars, _RZ, rz)
    wp.atomic_add(scalars, _RR, rr)


@wp.kernel
def cg_clear(scalars: wp.array[wp.float64]):
    """Zero the per-iteration slots (p.Ap, next r.z, r.r)."""
    scalars[_PAP] = wp.float64(0.0)
    scalars[_RZ_NEXT] = wp.float64(0.0)
    scalars[_RR] = wp.float64(0.0)


@wp.kernel
def cg_dot(a: wp.array[float], b: wp.array[float], count: int, scalars: wp.array[wp.float64]):
    """Add ``a.b`` to the p.Ap slot."""
    t = wp.tid()
    acc = wp.float64(0.0)
    for u in range(REDUCE_CHUNK):
        s = t * REDUCE_CHUNK + u
        if s < count:
            acc += wp.float64(a[s] * b[s])
    wp.atomic_add(scalars, _PAP, acc)


@wp.kernel
def cg_step(
    p: wp.array[float],
    ap: wp.array[float],
    inv_diag: wp.array[float],
    count: int,
    scalars: wp.array[wp.float64],
    x: wp.array[float],
    r: wp.array[float],
):
    """``x += alpha p``, ``r -= alpha A p``; adds the next ``r.M^-1 r`` and ``r.r``."""
    t = wp.tid()
    pap = scalars[_PAP]
    alpha = float(0.0)
    if pap > wp.float64(0.0):
        alpha = float(scalars[_RZ] / pap)
    rz = wp.float64(0.0)
    rr = wp.float64(0.0)
    for u in range(REDUCE_CHUNK):
        s = t * REDUCE_CHUNK + u
        if s < count:
            x[s] = x[s] + alpha * p[s]
            ri = r[s] - alpha * ap[s]
            r[s] = ri
            rz += wp.float64(ri * ri * inv_diag[s])
            rr += wp.float64(ri * ri)
    wp.atomic_add(scalars, _RZ_NEXT, rz)
    wp.atomic_add(scalars, _RR, rr)


@wp.kernel
def cg_direction(
    r: wp.array[float],
    inv_diag: wp.array[float],
    count: int,
    scalars: wp.array[wp.float64],
    p: wp.array[float],
):
    """``p = M^-1 r + beta p`` with ``beta = rz_next / rz``."""
    s = wp.tid()
    if s >= count:
        return
    rz = scalars[_RZ]
    beta = float(0.0)
    if rz > wp.float64(0.0):
        beta = float(scalars[_RZ_NEXT] / rz)
    p[s] = r[s] * inv_diag[s] + beta * p[s]


@wp.kernel
def cg_shift(scalars: wp.array[wp.float64]):
    """``rz = rz_next`` for the next iteration."""
    scalars[_RZ] = scalars[_RZ_NEXT]


@wp.kernel
def invert(diag: wp.array[float], count: int, out: wp.array[float]):
    """``out = 1 / diag`` (0 where the diagonal is 0)."""
    s = wp.tid()
    if s >= count:
        return
    d = diag[s]
    out[s] = wp.where(d > 0.0, 1.0 / d, 0.0)


# -- rays against the fitted function --------------------------------------------------------


@wp.kernel
def ray_anchor(
    f: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    ray_origin: wp.array[wp.vec3],
    ray_dir: wp.array[wp.vec3],
    light_code: wp.array[int],
    light_vec: wp.array[wp.vec3],
    anchor: wp.array[wp.vec3],
    kind: wp.array[int],
    normals: wp.array[wp.vec3],
):
    """Where each ray meets the zero set of ``f``, or, if it misses, comes nearest to it.

    The ray is clipped to the grid and marched in ``h/2`` steps. The first crossing from
    ``f > 0`` to ``f <= 0`` is refined by bisection (:data:`ANCHOR_CROSSING`); without one, the
    anchor is the step where ``|f|`` is smallest (:data:`ANCHOR_NEAREST`): a ray that passes
    beside the current surface still says where that surface should be. The constraint normal
    is evaluated at the anchor.
    """
    r = wp.tid()
    o = ray_origin[r]
    d = ray_dir[r]
    span = grid_span(f, origin, h, o, d)
    kind[r] = ANCHOR_NONE
    if span[0] > span[1]:
        return
    steps = wp.max(int(wp.ceil((span[1] - span[0]) / (0.5 * h))), 1)
    dt = (span[1] - span[0]) / float(steps)
    t_prev = span[0]
    f_prev = trilinear(f, origin, h, o + t_prev * d)
    t_best = t_prev
    f_best = wp.abs(f_prev)
    for s in range(1, steps + 1):
        t = span[0] + float(s) * dt
        v = trilinear(f, origin, h, o + t * d)
        if f_prev > 0.0 and v <= 0.0:
            x = o + bisect_crossing(f, origin, h, o, d, t_prev, t) * d
            anchor[r] = x
            kind[r] = ANCHOR_CROSSING
            normals[r] = reflection_normal(light_code[r], light_vec[r], d, x)
            return
        if wp.abs(v) < f_best:
            f_best = wp.abs(v)
            t_best = t
        t_prev = t
        f_prev = v
    x = o + t_best * d
    anchor[r] = x
    kind[r] = ANCHOR_NEAREST
    normals[r] = reflection_normal(light_code[r], light_vec[r], d, x)


@wp.kernel
def sample_gradient(
    f: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    xs: wp.array[wp.vec3],
    out: wp.array[wp.vec3],
):
    """Gradient of the trilinear interpolant of ``f`` at world points."""
    s = wp.tid()
    n = cell_of(f, origin, h, xs[s])
    out[s] = cell_gradient(f, n, cell_fraction(f, origin, h, xs[s], n), 1.0 / h)


@wp.kernel
def sample_value(
    f: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    xs: wp.array[wp.vec3],
    out: wp.array[float],
):
    """Trilinear value of ``f`` at world points."""
    s = wp.tid()
    out[s] = trilinear(f, origin, h, xs[s])


@wp.kernel
def resample(
    coarse: wp.array3d[float],
    ratio: float,
    fine: wp.array3d[float],
):
    """Trilinear prolongation of a coarse field onto a finer grid with the same first node.

    Both fields are in their own grid's voxels; ``ratio`` is the coarse voxel over the fine
    one, so fine node ``i`` sits at coarse index ``i / ratio`` and its value is the coarse
    value times ``ratio``.
    """
    i, j, k = wp.tid()
    x = wp.vec3(float(i), float(j), float(k))
    fine[i, j, k] = ratio * trilinear(coarse, wp.vec3(0.0, 0.0, 0.0), ratio, x)


@wp.kernel
def sphere_field(origin: wp.vec3, h: float, centre: wp.vec3, radius: float,
                 out: wp.array3d[float]):
    """Signed distance to a sphere (negative inside)."""
    i, j, k = wp.tid()
    x = origin + h * wp.vec3(float(i), float(j), float(k))
    out[i, j, k] = wp.length(x - centre) - radius


@wp.kernel
def quadric_field(start: wp.vec3, step: float, coeffs: wp.array[float], out_scale: float,
                  out: wp.array3d[float]):
    """First-order signed distance ``out_scale * q / |grad q|`` of a quadric.

    ``q(x) = A00 x^2 + A11 y^2 + A22 z^2 + 2 A01 xy + 2 A02 xz + 2 A12 yz + b.x + c`` in the
    quadric's normalised coordinates, node ``(i, j, k)`` at ``x = start + step (i, j, k)``
    (so no world coordinate, whatever its size, enters the arithmetic); coefficients in that
    order. Where ``|grad q|`` vanishes it is clamped, so that the field stays finite.
    """
    i, j, k = wp.tid()
    x = start + step * wp.vec3(float(i), float(j), float(k))
    q = (coeffs[0] * x[0] * x[0] + coeffs[1] * x[1] * x[1] + coeffs[2] * x[2] * x[2]
         + 2.0 * (coeffs[3] * x[0] * x[1] + coeffs[4] * x[0] * x[2] + coeffs[5] * x[1] * x[2])
         + coeffs[6] * x[0] + coeffs[7] * x[1] + coeffs[8] * x[2] + coeffs[9])
    g = wp.vec3(2.0 * (coeffs[0] * x[0] + coeffs[3] * x[1] + coeffs[4] * x[2]) + coeffs[6],
                2.0 * (coeffs[3] * x[0] + coeffs[1] * x[1] + coeffs[5] * x[2]) + coeffs[7],
                2.0 * (coeffs[4] * x[0] + coeffs[5] * x[1] + coeffs[2] * x[2]) + coeffs[8])
    gl = wp.max(wp.length(g), 1.0e-3 * (wp.abs(coeffs[0]) + wp.abs(coeffs[1]) + wp.abs(coeffs[2])
                                        + wp.length(wp.vec3(coeffs[6], coeffs[7], coeffs[8]))))
    out[i, j, k] = out_scale * q / gl


@wp.kernel
def scaled_copy(src: wp.array3d[float], factor: float, dst: wp.array3d[float]):
    """``dst = factor * src`` (a field in one level's voxels into world units)."""
    i, j, k = wp.tid()
    dst[i, j, k] = factor * src[i, j, k]


@wp.kernel
def torus_field(start: wp.vec3, step: float, axis: wp.vec3, major: float, minor: float,
                out: wp.array3d[float]):
    """Signed distance to a ring torus, node ``(i, j, k)`` at ``start + step (i, j, k)``.

    ``start`` is the grid's origin relative to the torus' centre; ``axis`` is a unit vector,
    ``major`` the core circle's radius and ``minor`` the tube's (negative inside the tube).
    """
    i, j, k = wp.tid()
    v = start + step * wp.vec3(float(i), float(j), float(k))
    z = wp.dot(v, axis)
    rho = wp.length(v - z * axis)
    out[i, j, k] = wp.sqrt((rho - major) * (rho - major) + z * z) - minor


@wp.kernel
def revolution_field(start: wp.vec3, step: float, axis: wp.vec3, h0: float, dh: float,
                     radii: wp.array[float], slopes: wp.array[float], out: wp.array3d[float]):
    """First-order distance to a surface of revolution, ``(rho - r(h)) / sqrt(1 + r'(h)^2)``.

    Node ``(i, j, k)`` at ``start + step (i, j, k)``, ``start`` relative to the axis' point at
    height 0; the profile ``r`` and its slope ``r'`` are given on knots ``h0 + dh m``,
    interpolated linearly and held constant beyond the ends (negative inside).
    """
    i, j, k = wp.tid()
    v = start + step * wp.vec3(float(i), float(j), float(k))
    h = wp.dot(v, axis)
    rho = wp.length(v - h * axis)
    last = radii.shape[0] - 1
    u = wp.clamp((h - h0) / dh, 0.0, float(last))
    m = wp.min(int(wp.floor(u)), last - 1)
    t = u - float(m)
    r = (1.0 - t) * radii[m] + t * radii[m + 1]
    s = (1.0 - t) * slopes[m] + t * slopes[m + 1]
    out[i, j, k] = (rho - r) / wp.sqrt(1.0 + s * s)
