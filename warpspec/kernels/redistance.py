"""Reinitialisation by fast sweeping, and distance to a point set (docs/DESIGN.md section 6).

Distances are computed in index units (``h = 1``) in a scratch array and scaled by the spacing
only when written back, so the sweeps never see the spacing. Two ways to run the sweeps share
one node update (:func:`_visit`):

- ``serial``: one thread does the 8 Gauss-Seidel sweeps of Zhao (2005) in order; the fastest on
  the CPU backend, which runs a launch serially anyway.
- ``split``: two CPU threads at once on two copies, one sweeping the 4 orderings that run up
  the third axis and one the 4 that run down it; each node then takes the smaller value. A
  distance's characteristics are straight lines from the nearest surface point, so each node
  is reached by one of the two, and both cores work: about 1.6 times faster than ``serial``.
  The result is an upper bound of the converged distance that equals the serial one next to
  the surface; only at a medial surface where the nearest zero set lies up the third axis on
  one side and down it on the other can it exceed the serial one (a few percent of the
  distance there, tested).
- ``planes``: the parallel sweeps of Detrixhe, Gibou and Min (2013): for each of the 8
  orderings, one launch per plane ``i' + j' + k' = L`` of the ordering's flipped coordinates.
  A node's update reads only its 6 axis neighbours; the 3 upwind ones lie on plane ``L - 1``
  (already swept) and the 3 downwind ones on plane ``L + 1`` (not yet swept), exactly as in
  the serial lexicographic order, so both methods give the same numbers. A thread writes only
  its own node and sets the "active" bit of its neighbours (on planes ``L +- 1``, which no
  thread of the launch clears), so a launch is race-free in any thread order.

A node is updated only while "active" (a neighbour changed since its last update: the locking
of Bak, McLaughlin and Renzi 2010), which skips most of the work of the later sweeps without
changing the result. The distance to a point set uses the same sweeps, passing each node the
nearest of its neighbours' nearest points (closest-point sweeping) instead of the Godunov
update.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import warp as wp

from .._parallel import cpu_cores, launch_halves, run_pair
from ..errors import InputError
from .band import band_slot

wp.set_module_options({"enable_backward": False})

__all__ = ["BAND_MODES", "METHODS", "Redistancer"]

BIG = wp.constant(1.0e30)
"""Start value of the nodes that the sweeps have not reached (finite: no inf in the output)."""

BAND_MODES = {"axis": 0, "gradient": 1}
"""Band initialisations accepted by :class:`Redistancer` and their kernel codes."""

METHODS = ("auto", "serial", "split", "planes")
"""Sweep methods accepted by :class:`Redistancer`."""

BAND_PASSES = 4
"""Default relaxation passes of :meth:`Redistancer.reinitialize_band`: on the octant at 64^3
with a band of 8 voxels, 4 passes reach the full reinitialisation's values within 4 h of the
surface to 8e-4 h (8 passes: 1e-6 h), at half the cost."""

# flags per node: bit 0 inside (phi < 0); bit 1 frozen (a band node, kept by the sweeps);
# bit 2 active (a neighbour changed since the node was last updated: the "locking" of Bak,
# McLaughlin and Renzi 2010, which skips the nodes that cannot change)
_INSIDE = wp.constant(1)
_FROZEN = wp.constant(2)
_ACTIVE = wp.constant(4)


@wp.func
def _crossing(p0: float, p1: float) -> float:
    """Distance in index units from a node (p0) to the zero crossing on the edge to p1, or BIG."""
    if (p0 < 0.0) != (p1 < 0.0):
        return p0 / (p0 - p1)
    return BIG


@wp.struct
class PointSet:
    """A point set for the distance sweeps, and the nearest known point of every node."""

    points: wp.array[wp.vec3]
    """World positions."""
    origin: wp.vec3
    """World position of node (0, 0, 0)."""
    inv_h: float
    """1 / spacing."""
    nearest: wp.array3d[wp.int32]
    """Index of the nearest known point per node, -1 for none."""


@wp.func
def _point_distance(pts: PointSet, q: int, g: wp.vec3) -> float:
    """Distance (index units) from grid position g to point q, or BIG for q < 0."""
    if q < 0:
        return BIG
    return wp.length((pts.points[q] - pts.origin) * pts.inv_h - g)


@wp.func
def _mark(flags: wp.array3d[wp.uint8], i: int, j: int, k: int):
    """Mark one node active (the flag byte is only ever or-ed with the same bit meanwhile)."""
    flags[i, j, k] = flags[i, j, k] | wp.uint8(_ACTIVE)


@wp.func
def _godunov(a: float, b: float, c: float, old: float) -> float:
    """Godunov solution of |grad d| = 1 (h = 1) from the smaller neighbour on each axis.

    Returns ``old`` at once if no update can lower it: the update is at least the smallest
    neighbour + 1/sqrt(3).
    """
    if wp.min(a, wp.min(b, c)) + 0.5773 >= old:
        return old
    # sort a <= b <= c
    if a > b:
        t = a
        a = b
        b = t
    if b > c:
        t = b
        b = c
        c = t
    if a > b:
        t = a
        a = b
        b = t
    # solve relative to the smallest value: float32 keeps its precision far from the surface
    u = 1.0
    b = b - a
    if u > b:
        u = 0.5 * (b + wp.sqrt(2.0 - b * b))
        c = c - a
        if u > c:
            s = b + c
            u = (s + wp.sqrt(wp.max(s * s - 3.0 * (b * b + c * c - 1.0), 0.0))) / 3.0
    return a + u


@wp.func
def _visit_distance(d: wp.array3d[float], flags: wp.array3d[wp.uint8], i: int, j: int, k: int):
    """Godunov update of |grad d| = 1 (h = 1) at one node; wake the neighbours it may lower.

    The 6 axis neighbours are clamped at the border (the same as one-sided there). A neighbour
    whose value is not above the new one cannot use it as an upwind value, so it is not woken.
    """
    nx = d.shape[0]
    ny = d.shape[1]
    nz = d.shape[2]
    xm = d[wp.max(i - 1, 0), j, k]
    xp = d[wp.min(i + 1, nx - 1), j, k]
    ym = d[i, wp.max(j - 1, 0), k]
    yp = d[i, wp.min(j + 1, ny - 1), k]
    zm = d[i, j, wp.max(k - 1, 0)]
    zp = d[i, j, wp.min(k + 1, nz - 1)]
    old = d[i, j, k]
    u = _godunov(wp.min(xm, xp), wp.min(ym, yp), wp.min(zm, zp), old)
    if u < old:
        d[i, j, k] = u
        if i > 0 and xm > u:
            _mark(flags, i - 1, j, k)
        if i < nx - 1 and xp > u:
            _mark(flags, i + 1, j, k)
        if j > 0 and ym > u:
            _mark(flags, i, j - 1, k)
        if j < ny - 1 and yp > u:
            _mark(flags, i, j + 1, k)
        if k > 0 and zm > u:
            _mark(flags, i, j, k - 1)
        if k < nz - 1 and zp > u:
            _mark(flags, i, j, k + 1)


@wp.func
def _nearest_update(pts: PointSet, i: int, j: int, k: int) -> bool:
    """Take the nearest point among this node's and its 6 neighbours' nearest points."""
    nx = pts.nearest.shape[0]
    ny = pts.nearest.shape[1]
    nz = pts.nearest.shape[2]
    g = wp.vec3(float(i), float(j), float(k))
    old = pts.nearest[i, j, k]
    best = old
    bd = _point_distance(pts, old, g)
    q = pts.nearest[wp.max(i - 1, 0), j, k]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    q = pts.nearest[wp.min(i + 1, nx - 1), j, k]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    q = pts.nearest[i, wp.max(j - 1, 0), k]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    q = pts.nearest[i, wp.min(j + 1, ny - 1), k]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    q = pts.nearest[i, j, wp.max(k - 1, 0)]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    q = pts.nearest[i, j, wp.min(k + 1, nz - 1)]
    dq = _point_distance(pts, q, g)
    if dq < bd:
        bd = dq
        best = q
    if best != old:
        pts.nearest[i, j, k] = best
        return True
    return False


@wp.func
def _visit(
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    pts: PointSet,
    mode: int,
    i: int,
    j: int,
    k: int,
):
    """Update an active, unfrozen node (mode 0: distance ``d``; 1: nearest point of ``pts``).

    Reads the node and its 6 axis neighbours; writes only the node and its neighbours' active
    bits (to wake them for the next visit).
    """
    f = int(flags[i, j, k])
    if (f & (_ACTIVE + _FROZEN)) != _ACTIVE:
        return
    flags[i, j, k] = wp.uint8(f - _ACTIVE)
    if mode == 0:
        _visit_distance(d, flags, i, j, k)
    elif _nearest_update(pts, i, j, k):
        if i > 0:
            _mark(flags, i - 1, j, k)
        if i < flags.shape[0] - 1:
            _mark(flags, i + 1, j, k)
        if j > 0:
            _mark(flags, i, j - 1, k)
        if j < flags.shape[1] - 1:
            _mark(flags, i, j + 1, k)
        if k > 0:
            _mark(flags, i, j, k - 1)
        if k < flags.shape[2] - 1:
            _mark(flags, i, j, k + 1)


@wp.func
def _band_distance(phi: wp.array3d[float], i: int, j: int, k: int, mode: int) -> float:
    """Distance (index units) from a node to the zero set if it is next to a sign change, or BIG."""
    nx = phi.shape[0]
    ny = phi.shape[1]
    nz = phi.shape[2]
    im = wp.max(i - 1, 0)
    ip = wp.min(i + 1, nx - 1)
    jm = wp.max(j - 1, 0)
    jp = wp.min(j + 1, ny - 1)
    km = wp.max(k - 1, 0)
    kp = wp.min(k + 1, nz - 1)
    p = phi[i, j, k]
    if p == 0.0:
        return 0.0
    pxm = phi[im, j, k]
    pxp = phi[ip, j, k]
    pym = phi[i, jm, k]
    pyp = phi[i, jp, k]
    pzm = phi[i, j, km]
    pzp = phi[i, j, kp]
    lo = wp.min(wp.min(wp.min(pxm, pxp), wp.min(pym, pyp)), wp.min(pzm, pzp))
    hi = wp.max(wp.max(wp.max(pxm, pxp), wp.max(pym, pyp)), wp.max(pzm, pzp))
    if (p > 0.0 and lo >= 0.0) or (p < 0.0 and hi < 0.0):
        return BIG  # no sign change: most nodes
    dx = wp.min(_crossing(p, pxm), _crossing(p, pxp))
    dy = wp.min(_crossing(p, pym), _crossing(p, pyp))
    dz = wp.min(_crossing(p, pzm), _crossing(p, pzp))
    dmin = wp.min(dx, wp.min(dy, dz))
    if dmin >= BIG:
        return BIG
    if dmin <= 0.0:
        return 0.0  # underflow: a crossing closer than float32 resolves
    # 1 / sqrt(sum 1 / d_axis^2), scaled by dmin so that no term overflows
    rx = dmin / dx
    ry = dmin / dy
    rz = dmin / dz
    dist = dmin / wp.sqrt(rx * rx + ry * ry + rz * rz)
    if mode == 1:
        gx = (pxp - pxm) / float(ip - im)
        gy = (pyp - pym) / float(jp - jm)
        gz = (pzp - pzm) / float(kp - km)
        g = wp.sqrt(gx * gx + gy * gy + gz * gz)
        if g > 0.0:
            # a crossing on an edge is a point of the surface: the distance is at most dmin
            dist = wp.min(wp.abs(p) / g, dmin)
    return dist


# The element-wise kernels run over (i, j, block of k): a block of ``chunk`` nodes along k per
# thread (the whole row on the CPU, where each thread has a fixed cost; 1 on CUDA).


@wp.kernel
def init_band_kernel(
    i0: int,
    phi: wp.array3d[float],
    mode: int,
    chunk: int,
    cap: float,
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    count: wp.array[wp.int32],
):
    """Freeze the nodes next to a sign change at their distance (index units); ``cap`` elsewhere.

    No node is marked active here: :func:`activate_front_kernel` wakes the neighbours of the
    frozen nodes, the only ones that the first sweep can change.
    """
    i, j, kb = wp.tid()
    i = i + i0
    frozen = wp.int32(0)
    for c in range(chunk):
        k = kb * chunk + c
        if k < phi.shape[2]:
            dist = _band_distance(phi, i, j, k, mode)
            f = wp.int32(0)
            if phi[i, j, k] < 0.0:
                f = _INSIDE
            if dist < BIG:
                f = f + _FROZEN
                frozen = frozen + 1
            else:
                dist = cap
            d[i, j, k] = dist
            flags[i, j, k] = wp.uint8(f)
    if frozen > 0:
        wp.atomic_add(count, 0, frozen)


@wp.func
def _is_frozen(flags: wp.array3d[wp.uint8], i: int, j: int, k: int) -> int:
    return int(flags[i, j, k]) & _FROZEN


@wp.kernel
def activate_front_kernel(
    i0: int,chunk: int, flags: wp.array3d[wp.uint8], rows: wp.array2d[wp.uint8]):
    """Mark active the unfrozen nodes with a frozen axis neighbour, and their rows ``(i, j)``.

    Every other node starts at the same value as all its neighbours, so its first update could
    not lower it: waking only this front gives the sweeps exactly the same updates.
    """
    i, j, kb = wp.tid()
    i = i + i0
    nx = flags.shape[0]
    ny = flags.shape[1]
    nz = flags.shape[2]
    any_active = int(0)
    for c in range(chunk):
        k = kb * chunk + c
        if k < nz:
            f = int(flags[i, j, k])
            if (f & _FROZEN) == 0:
                near = _is_frozen(flags, wp.max(i - 1, 0), j, k)
                near = near | _is_frozen(flags, wp.min(i + 1, nx - 1), j, k)
                near = near | _is_frozen(flags, i, wp.max(j - 1, 0), k)
                near = near | _is_frozen(flags, i, wp.min(j + 1, ny - 1), k)
                near = near | _is_frozen(flags, i, j, wp.max(k - 1, 0))
                near = near | _is_frozen(flags, i, j, wp.min(k + 1, nz - 1))
                if near != 0:
                    flags[i, j, k] = wp.uint8(f + _ACTIVE)
                    any_active = 1
    if any_active != 0:
        rows[i, j] = wp.uint8(1)


@wp.func
def _wake(flags: wp.array[wp.uint8], rows: wp.array[wp.uint8], t: int, r: int):
    """Mark flat node ``t`` active and its row ``r`` as holding an active node."""
    flags[t] = flags[t] | wp.uint8(_ACTIVE)
    rows[r] = wp.uint8(1)


@wp.kernel
def serial_sweep_kernel(
    d: wp.array[float],
    flags: wp.array[wp.uint8],
    rows: wp.array[wp.uint8],
    shape: wp.vec3i,
    passes: int,
    first: int,
    orders: int,
):
    """Gauss-Seidel sweeps of the distance in one thread (the CPU).

    Orderings ``first`` to ``first + orders - 1`` (of the 8), ``passes`` times. With all 8
    orderings, the same updates in the same order as :func:`sweep_kernel` (so the same
    numbers) on flattened arrays: a neighbour is an offset (no index arithmetic per read),
    and a row ``(i, j)`` whose ``rows`` byte is clear holds no active node and is skipped
    whole.
    """
    nx = shape[0]
    ny = shape[1]
    nz = shape[2]
    sx = ny * nz
    for step in range(orders * passes):
        o = first + step % orders
        for a in range(nx):
            i = a
            if o & 1:
                i = nx - 1 - a
            for b in range(ny):
                j = b
                if o & 2:
                    j = ny - 1 - b
                r = i * ny + j
                if rows[r] == wp.uint8(0):
                    continue
                rows[r] = wp.uint8(0)
                base = r * nz
                for c in range(nz):
                    k = c
                    if o & 4:
                        k = nz - 1 - c
                    t = base + k
                    f = int(flags[t])
                    if (f & (_ACTIVE + _FROZEN)) != _ACTIVE:
                        continue
                    flags[t] = wp.uint8(f - _ACTIVE)
                    old = d[t]
                    # clamped neighbours: the node itself at the border
                    xm = old
                    if i > 0:
                        xm = d[t - sx]
                    xp = old
                    if i < nx - 1:
                        xp = d[t + sx]
                    ym = old
                    if j > 0:
                        ym = d[t - nz]
                    yp = old
                    if j < ny - 1:
                        yp = d[t + nz]
                    zm = old
                    if k > 0:
                        zm = d[t - 1]
                    zp = old
                    if k < nz - 1:
                        zp = d[t + 1]
                    u = _godunov(wp.min(xm, xp), wp.min(ym, yp), wp.min(zm, zp), old)
                    if u < old:
                        d[t] = u
                        if i > 0 and xm > u:
                            _wake(flags, rows, t - sx, r - ny)
                        if i < nx - 1 and xp > u:
                            _wake(flags, rows, t + sx, r + ny)
                        if j > 0 and ym > u:
                            _wake(flags, rows, t - nz, r - 1)
                        if j < ny - 1 and yp > u:
                            _wake(flags, rows, t + nz, r + 1)
                        if k > 0 and zm > u:
                            _wake(flags, rows, t - 1, r)
                        if k < nz - 1 and zp > u:
                            _wake(flags, rows, t + 1, r)


@wp.kernel
def sweep_kernel(
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    pts: PointSet,
    mode: int,
    passes: int,
    order: int,
    level: int,
    a0: int,
    b0: int,
):
    """Sweep the nodes of plane a + b + c = level of one ordering, or (level < 0) all of them.

    With ``level >= 0`` a thread updates one node of that plane of ordering ``order`` (bit set:
    axis flipped); with ``level < 0`` a single thread does the 8 orderings ``passes`` times.
    """
    ta, tb = wp.tid()
    nx = flags.shape[0]
    ny = flags.shape[1]
    nz = flags.shape[2]
    if level >= 0:
        a = a0 + ta
        b = b0 + tb
        c = level - a - b
        if c < 0 or c >= nz:
            return
        i = a
        if order & 1:
            i = nx - 1 - a
        j = b
        if order & 2:
            j = ny - 1 - b
        k = c
        if order & 4:
            k = nz - 1 - c
        _visit(d, flags, pts, mode, i, j, k)
        return
    for step in range(8 * passes):
        o = step % 8
        for a in range(nx):
            i = a
            if o & 1:
                i = nx - 1 - a
            for b in range(ny):
                j = b
                if o & 2:
                    j = ny - 1 - b
                for c in range(nz):
                    k = c
                    if o & 4:
                        k = nz - 1 - c
                    _visit(d, flags, pts, mode, i, j, k)


@wp.kernel
def apply_sign_kernel(
    i0: int,
    d: wp.array3d[float],
    twin: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    count: wp.array[wp.int32],
    h: float,
    chunk: int,
    phi: wp.array3d[float],
):
    """Write the signed distance, the smaller of ``d`` and ``twin``, back into phi.

    ``twin`` is ``d`` itself unless the sweeps were split between two threads. ``phi`` is
    left unchanged if nothing was frozen.
    """
    i, j, kb = wp.tid()
    i = i + i0
    if count[0] == 0:
        return
    for c in range(chunk):
        k = kb * chunk + c
        if k < phi.shape[2]:
            v = wp.min(d[i, j, k], twin[i, j, k]) * h
            if int(flags[i, j, k]) & _INSIDE:
                v = -v
            phi[i, j, k] = v


@wp.kernel
def add_count_kernel(src: wp.array[wp.int32], dst: wp.array[wp.int32]):
    """Add one counter into another (the two halves' counts of a split launch)."""
    dst[0] = dst[0] + src[0]


@wp.kernel
def band_init_kernel(
    phi: wp.array3d[float],
    band: wp.array[int],
    count: wp.array[int],
    mode: int,
    cap: float,
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    frozen: wp.array[wp.int32],
):
    """Freeze the band nodes next to a sign change; start the others at ``cap`` (index units)."""
    s = wp.tid()
    n = band_slot(band, count, s, 0, wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2]))
    if n[0] < 0:
        return
    i = n[0]
    j = n[1]
    k = n[2]
    dist = _band_distance(phi, i, j, k, mode)
    f = wp.int32(0)
    if phi[i, j, k] < 0.0:
        f = _INSIDE
    if dist < BIG:
        f = f + _FROZEN
        d[i, j, k] = dist
        wp.atomic_add(frozen, 0, 1)
    else:
        f = f + _ACTIVE
        d[i, j, k] = cap
    flags[i, j, k] = wp.uint8(f)


@wp.kernel
def band_sweep_kernel(
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    band: wp.array[int],
    count: wp.array[int],
    reverse: int,
):
    """One relaxation pass over the band: Godunov updates of its active, unfrozen nodes.

    On the CPU the pass is a Gauss-Seidel sweep in index order (or its reverse). On CUDA the
    threads race, but every update only lowers a value toward the same fixed point, so
    enough passes reach it in any order. Nodes off the band read as ``BIG``: never upwind.
    """
    s = wp.tid()
    n = band_slot(band, count, s, reverse, wp.vec3i(d.shape[0], d.shape[1], d.shape[2]))
    if n[0] < 0:
        return
    f = int(flags[n[0], n[1], n[2]])
    if (f & (_ACTIVE + _FROZEN)) != _ACTIVE:
        return
    flags[n[0], n[1], n[2]] = wp.uint8(f - _ACTIVE)
    _visit_distance(d, flags, n[0], n[1], n[2])


@wp.kernel
def band_sign_kernel(
    d: wp.array3d[float],
    flags: wp.array3d[wp.uint8],
    band: wp.array[int],
    count: wp.array[int],
    frozen: wp.array[wp.int32],
    h: float,
    first: int,
    phi: wp.array3d[float],
):
    """Write the signed distance back into the band's nodes (nothing if nothing was frozen).

    Thread ``t`` takes slot ``first + t``.
    """
    s = first + wp.tid()
    if frozen[0] == 0:
        return
    n = band_slot(band, count, s, 0, wp.vec3i(d.shape[0], d.shape[1], d.shape[2]))
    if n[0] < 0:
        return
    v = d[n[0], n[1], n[2]] * h
    if int(flags[n[0], n[1], n[2]]) & _INSIDE:
        v = -v
    phi[n[0], n[1], n[2]] = v


@wp.kernel
def clear_kernel(chunk: int, pts: PointSet, out: wp.array3d[float], flags: wp.array3d[wp.uint8]):
    """Start every node with no nearest point, active and unfrozen; ``out`` at BIG."""
    i, j, kb = wp.tid()
    for c in range(chunk):
        k = kb * chunk + c
        if k < out.shape[2]:
            out[i, j, k] = BIG
            pts.nearest[i, j, k] = -1
            flags[i, j, k] = wp.uint8(_ACTIVE)


@wp.kernel
def seed_points_kernel(pts: PointSet, phase: int, best: wp.array3d[float]):
    """Seed the 4x4x4 nodes around each point with their nearest point, in two launches.

    Phase 0: atomic min of the exact distance into ``best``; phase 1: a point whose distance
    equals that minimum writes its index (ties: any of them).
    """
    p, a, b, c = wp.tid()
    g = (pts.points[p] - pts.origin) * pts.inv_h
    # the block of nodes floor(g) - 1 .. floor(g) + 2, shifted to lie inside the grid
    i = int(wp.clamp(wp.floor(g[0]) - 1.0, 0.0, float(wp.max(best.shape[0] - 4, 0)))) + a
    j = int(wp.clamp(wp.floor(g[1]) - 1.0, 0.0, float(wp.max(best.shape[1] - 4, 0)))) + b
    k = int(wp.clamp(wp.floor(g[2]) - 1.0, 0.0, float(wp.max(best.shape[2] - 4, 0)))) + c
    if i >= best.shape[0] or j >= best.shape[1] or k >= best.shape[2]:
        return
    dist = _point_distance(pts, p, wp.vec3(float(i), float(j), float(k)))
    if phase == 0:
        wp.atomic_min(best, i, j, k, dist)
    elif dist == best[i, j, k]:
        pts.nearest[i, j, k] = p


@wp.kernel
def write_capped_kernel(pts: PointSet, h: float, cap: float, chunk: int, out: wp.array3d[float]):
    """Write the distance to each node's nearest point in world units, clamped to ``cap``."""
    i, j, kb = wp.tid()
    for c in range(chunk):
        k = kb * chunk + c
        if k < out.shape[2]:
            g = wp.vec3(float(i), float(j), float(k))
            out[i, j, k] = wp.min(_point_distance(pts, pts.nearest[i, j, k], g) * h, cap)


class Redistancer:
    """Fast-sweeping reinitialisation and point-set distance on one grid and one device.

    The scratch arrays (a float32 distance, which :meth:`point_distance` reuses as the int32
    index of each node's nearest point, and a uint8 flag per node: 5 bytes per node) and, for
    the ``planes`` method, the recorded plane launches are made once here, so
    :meth:`reinitialize` is nothing but launches (no allocation, no host synchronisation) and
    can be captured in a Warp graph.

    Args:
        shape: Number of nodes along each axis.
        spacing: Node spacing ``h`` in world units.
        device: Warp device (or its name) to run on.
        method: ``"serial"`` (one thread sweeps), ``"split"`` (two CPU threads, one for the
            4 orderings that run up the third axis and one for the 4 that run down it, on two
            copies, then the smaller value of each node: about twice as fast on two cores),
            ``"planes"`` (parallel sweeps over the planes ``i + j + k = const``, for CUDA) or
            ``"auto"`` (planes on CUDA; on the CPU, split where the process has two cores,
            else serial).
        band: How the nodes next to a sign change get their distance: ``"axis"`` (the linear
            zero crossing along each axis, combined as ``1 / sqrt(sum 1 / d_axis^2)``) or
            ``"gradient"`` (``|phi| / |grad phi|`` with central differences, one-sided at the
            border, at most the nearest axis crossing).
        passes: How many times the 8 sweeps are repeated.

    Raises:
        InputError: If ``method`` or ``band`` is unknown, ``passes`` is below 1, ``spacing`` is
            not positive or ``shape`` is not 3 positive sizes.
    """

    def __init__(
        self,
        shape: tuple[int, int, int],
        spacing: float,
        device: wp.context.Device | str,
        *,
        method: str = "auto",
        band: str = "axis",
        passes: int = 1,
    ) -> None:
        shape = tuple(int(s) for s in shape)
        if len(shape) != 3 or min(shape) < 1:
            raise InputError(f"shape: must be 3 positive sizes, got {shape}")
        if not spacing > 0.0:
            raise InputError(f"spacing: must be positive, got {spacing}")
        if method not in METHODS:
            raise InputError(f"method: must be one of {METHODS}, got {method!r}")
        if band not in BAND_MODES:
            raise InputError(f"band: must be one of {tuple(BAND_MODES)}, got {band!r}")
        if int(passes) < 1:
            raise InputError(f"passes: must be at least 1, got {passes}")
        self.device = wp.get_device(device)
        self.shape = shape
        self.spacing = float(spacing)
        self.band = band
        self.passes = int(passes)
        if method == "auto":
            if self.device.is_cuda:
                method = "planes"
            else:
                method = "split" if cpu_cores() >= 2 else "serial"
        if method == "split" and self.device.is_cuda:
            raise InputError("method: 'split' runs on the CPU only; use 'planes' on CUDA")
        self.method = method
        # element-wise kernels: a whole row of k per thread on the CPU, one node on CUDA
        self._chunk = 1 if self.device.is_cuda else shape[2]
        self._rows = (shape[0], shape[1], (shape[2] + self._chunk - 1) // self._chunk)
        self.distance = wp.empty(shape, dtype=float, device=self.device)
        """Scratch: unsigned distance in index units."""
        self.flags = wp.empty(shape, dtype=wp.uint8, device=self.device)
        """Scratch: inside, frozen and active bits per node."""
        self._active_rows = wp.zeros(shape[:2], dtype=wp.uint8, device=self.device)
        # per row (i, j): may hold an active node (the serial distance sweeps skip the others)
        if method == "split":  # the second thread's copy of the distance, flags and rows
            self._twin = (wp.empty(shape, dtype=float, device=self.device),
                          wp.empty(shape, dtype=wp.uint8, device=self.device),
                          wp.zeros(shape[:2], dtype=wp.uint8, device=self.device))
        self._count_b = wp.zeros(1, dtype=wp.int32, device=self.device)  # the second half's
        self.band_count = wp.zeros(1, dtype=wp.int32, device=self.device)
        """Number of band nodes found by the last :meth:`reinitialize` (0: no zero crossing)."""
        # the nearest-point index of point_distance shares the memory of `distance`
        nearest = wp.array(ptr=self.distance.ptr, dtype=wp.int32, shape=shape, device=self.device)
        self._no_points = self._point_set(wp.empty(0, dtype=wp.vec3, device=self.device), nearest)
        self._points = self._no_points
        self._plane_launches = self._record_planes() if method == "planes" else []

    def _point_set(
        self, points: wp.array, nearest: wp.array3d, origin: wp.vec3 | None = None
    ) -> PointSet:
        pts = PointSet()
        pts.points = points
        pts.origin = wp.vec3(0.0, 0.0, 0.0) if origin is None else wp.vec3(*origin)
        pts.inv_h = 1.0 / self.spacing
        pts.nearest = nearest
        return pts

    def _record_planes(self) -> list[wp.Launch]:
        nx, ny, nz = self.shape
        launches = []
        for order in range(8):
            for level in range(nx + ny + nz - 2):
                a_lo = max(0, level - (ny - 1) - (nz - 1))
                a_hi = min(nx - 1, level)
                b_lo = max(0, level - a_hi - (nz - 1))
                b_hi = min(ny - 1, level - a_lo)
                launches.append(
                    wp.launch(
                        sweep_kernel,
                        dim=(a_hi - a_lo + 1, b_hi - b_lo + 1),
                        inputs=[self.distance, self.flags, self._points, 0, 1]
                        + [order, level, a_lo, b_lo],
                        device=self.device,
                        record_cmd=True,
                    )
                )
        return launches

    def _check(self, array: wp.array, name: str) -> None:
        if tuple(array.shape) != self.shape or array.device != self.device:
            raise InputError(
                f"{name}: expected shape {self.shape} on {self.device}, "
                f"got {tuple(array.shape)} on {array.device}"
            )
        if array.dtype != wp.float32:
            raise InputError(f"{name}: expected float32, got {array.dtype.__name__}")

    def _launch_rows(self, kernel: wp.Kernel, args: Callable[[int], list]) -> None:
        """Launch a kernel over the rows ``(i, j, block of k)``, its first argument ``i0``.

        On the CPU two threads take half the ``i`` each; ``args(half)`` gives the rest of the
        arguments for half 0 or 1.
        """
        def launch(first: int, count: int, half: int) -> None:
            wp.launch(kernel, dim=(count, self._rows[1], self._rows[2]),
                      inputs=[first, *args(half)], device=self.device)

        launch_halves(launch, self.shape[0], self.device, nodes=math.prod(self.shape))

    def _serial_sweeps(self, distance: wp.array, flags: wp.array, rows: wp.array, *,
                       passes: int, first: int = 0, orders: int = 8) -> None:
        wp.launch(
            serial_sweep_kernel,
            dim=1,
            inputs=[distance.flatten(), flags.flatten(), rows.flatten(),
                    wp.vec3i(*self.shape), passes, first, orders],
            device=self.device,
        )

    def _sweep(self, pts: PointSet) -> wp.array:
        """Run the sweeps; returns the array whose minimum with :attr:`distance` is the result."""
        mode = 0 if pts is self._no_points else 1
        if (self.method == "split" and mode == 0 and self.passes == 1
                and not self.device.is_capturing):  # a worker thread's launch is not captured
            twin = self._twin
            for copy, original in zip(twin, (self.distance, self.flags, self._active_rows),
                                      strict=True):
                wp.copy(copy, original)
            run_pair(
                lambda: self._serial_sweeps(self.distance, self.flags, self._active_rows,
                                            passes=1, first=0, orders=4),
                lambda: self._serial_sweeps(*twin, passes=1, first=4, orders=4),
            )
            return twin[0]
        if self.method in ("serial", "split") and mode == 0:
            self._serial_sweeps(self.distance, self.flags, self._active_rows,
                                passes=self.passes)
            return self.distance
        if self.method in ("serial", "split"):
            wp.launch(
                sweep_kernel,
                dim=(1, 1),
                inputs=[self.distance, self.flags, pts, mode, self.passes, 0, -1, 0, 0],
                device=self.device,
            )
            return self.distance
        if pts is not self._points:
            # rebind the recorded launches (host-side only)
            for launch in self._plane_launches:
                launch.set_param_by_name("pts", pts)
                launch.set_param_by_name("mode", mode)
            self._points = pts
        for _ in range(self.passes):
            for launch in self._plane_launches:
                launch.launch()
        return self.distance

    def reinitialize(self, phi: wp.array3d, *, cap: float | None = None) -> wp.array:
        """Reset ``phi`` in place to the signed distance to its zero set.

        The nodes next to a sign change (along any axis) get their distance from the band
        formula and are frozen; every other node gets the fast-sweeping distance; signs are
        kept. A node where ``phi`` is exactly 0 is a band node at distance 0. If ``phi`` has no
        sign change and no zero, there is nothing to measure from: ``phi`` is left unchanged
        and the returned counter reads 0.

        With ``cap`` the unknown nodes start at ``cap`` voxel widths instead of "far": the
        result is then exactly ``sign(phi) * min(d, cap * h)`` (a node's Godunov value depends
        only on neighbours with smaller values, so capping changes nothing below the cap), and
        the sweeps touch only the nodes within ``cap`` of the zero set. Use it when nothing
        reads the far field's distances (a narrow-band solver reads only their sign).

        Args:
            phi: Level set of shape ``shape``, float32, on this device.
            cap: Largest distance computed, in voxel widths (positive); ``None``: no cap.

        Returns:
            :attr:`band_count`, a device array of one int32: the number of band nodes, 0 when
            ``phi`` had no zero crossing. Reading it (``.numpy()``) synchronises.

        Raises:
            InputError: If ``phi`` does not have this shape, device and dtype, or ``cap`` is
                not positive.
        """
        self._check(phi, "phi")
        if cap is None:
            start = float(BIG)
        elif cap > 0.0:
            start = float(cap)
        else:
            raise InputError(f"cap: must be a positive number of voxel widths, got {cap!r}")
        self.band_count.zero_()
        self._count_b.zero_()
        self._active_rows.zero_()
        counts = (self.band_count, self._count_b)
        self._launch_rows(init_band_kernel,
                          lambda half: [phi, BAND_MODES[self.band], self._chunk, start,
                                        self.distance, self.flags, counts[half]])
        wp.launch(add_count_kernel, dim=1, inputs=[self._count_b, self.band_count],
                  device=self.device)
        self._launch_rows(activate_front_kernel,
                          lambda half: [self._chunk, self.flags, self._active_rows])
        twin = self._sweep(self._no_points)
        self._launch_rows(apply_sign_kernel,
                          lambda half: [self.distance, twin, self.flags, self.band_count,
                                        self.spacing, self._chunk, phi])
        return self.band_count

    def reinitialize_band(
        self,
        phi: wp.array3d,
        band: wp.array,
        count: wp.array,
        *,
        size: int,
        width: float,
        passes: int | None = None,
    ) -> wp.array:
        """Reset the nodes of a narrow band of ``phi`` to the signed distance, in place.

        Only the band's nodes are read as unknowns and written; every other node is left as
        it is and seen as far away. Within the band the result is the fast-sweeping one, for
        nodes whose nearest surface point the band connects them to (all of them but a thin
        shell at the band's edge, when ``width`` exceeds the band's half-width).

        Args:
            phi: Level set of shape ``shape``, float32, on this device.
            band: The band's nodes, as :func:`~warpspec.kernels.band.build_band`
                encodes them.
            count: One int: how many entries of ``band`` are valid.
            size: Threads to launch: the band's size if known on the host, else the capacity
                of ``band`` (threads past ``count`` return at once).
            width: Start value of the band's unknown nodes, in voxel widths (above the band's
                half-width).
            passes: Relaxation passes over the band, alternately forward and backward. On the
                octant at 64^3 with ``width=8``, 8 passes reach the full reinitialisation's
                values within 4 h of the surface to 1e-6 h (4 passes: 8e-4 h).

        Returns:
            :attr:`band_count`: the number of frozen nodes (0: no zero crossing in the band,
            ``phi`` unchanged).
        """
        self._check(phi, "phi")
        if passes is None:
            passes = BAND_PASSES
        self.band_count.zero_()
        self.distance.fill_(float(BIG))
        self.flags.zero_()
        if size == 0:
            return self.band_count
        wp.launch(band_init_kernel, dim=size,
                  inputs=[phi, band, count, BAND_MODES[self.band], float(width)],
                  outputs=[self.distance, self.flags, self.band_count], device=self.device)
        for p in range(passes):
            wp.launch(band_sweep_kernel, dim=size,
                      inputs=[self.distance, self.flags, band, count, p % 2],
                      device=self.device)
        launch_halves(
            lambda first, threads, _half: wp.launch(
                band_sign_kernel, dim=threads,
                inputs=[self.distance, self.flags, band, count, self.band_count,
                        self.spacing, first], outputs=[phi], device=self.device),
            size, self.device)
        return self.band_count

    def point_distance(
        self,
        points: wp.array,
        origin: wp.vec3 | tuple[float, float, float],
        out: wp.array3d,
        *,
        cap: float | None = None,
    ) -> None:
        """Write the unsigned distance from every node to a point set into ``out``.

        The 4x4x4 nodes around each point (shifted to lie inside the grid) are seeded with
        their nearest such point (atomic min, so any number of points in any thread order); the
        sweeps then pass each node the nearest of its neighbours' nearest points (the
        closest-point variant of fast sweeping: exact but at rare nodes where Voronoi cells
        meet in a sliver), and ``out`` gets the Euclidean distance to it. With no points
        every node reads ``1e30 * h`` (or ``cap``).

        Args:
            points: World positions, ``wp.array`` of ``wp.vec3`` on this device.
            origin: World position of node ``(0, 0, 0)``.
            out: Output of shape ``shape``, float32, on this device; world units.
            cap: If given, distances above it are clamped to it.

        Raises:
            InputError: If ``out`` or ``points`` does not match this grid and device.
        """
        self._check(out, "out")
        if points.device != self.device or points.dtype != wp.vec3:
            raise InputError(
                f"points: expected a wp.vec3 array on {self.device}, "
                f"got {points.dtype.__name__} on {points.device}"
            )
        pts = self._point_set(points, self._no_points.nearest, origin)
        wp.launch(
            clear_kernel,
            dim=self._rows,
            inputs=[self._chunk, pts],
            outputs=[out, self.flags],
            device=self.device,
        )
        if points.shape[0] > 0:
            for phase in range(2):
                wp.launch(
                    seed_points_kernel,
                    dim=(points.shape[0], 4, 4, 4),
                    inputs=[pts, phase, out],
                    device=self.device,
                )
        self._sweep(pts)
        cap = float(BIG) * self.spacing if cap is None else float(cap)
        wp.launch(
            write_capped_kernel,
            dim=self._rows,
            inputs=[pts, self.spacing, cap, self._chunk],
            outputs=[out],
            device=self.device,
        )
