"""Marching cubes on the device, over the whole grid or over the cells of a narrow band.

One vertex per grid edge that changes sign (``phi >= 0`` on one end, ``phi < 0`` on the
other), at the linear zero crossing; faces index these edge vertices, so a vertex is shared
by every face around it without merging positions. The case tables are Warp's
(:class:`warp.geometry.IsoSurfaceMarchingCubes`, the classic Lorensen-Cline cases), with a
corner's bit set where ``phi >= 0``: their triangles then wind outward, toward ``phi > 0``
(a sphere has positive volume; tests/test_marching.py checks it).

Three launches, each over the nodes (or the band's nodes, as
:func:`~warpspec.kernels.band.build_band` encodes them), with one host read between
the first and the others (to size the output):

1. :func:`count_kernel`: how many crossing edges and triangles;
2. :func:`vertices_kernel`: a slot per crossing edge (its node, axis and crossing ``t``),
   recorded in the per-node ``edge_slot`` table;
3. :func:`faces_kernel`: the triangles of each cell, as edge slots.
"""

from __future__ import annotations

import numpy as np
import warp as wp
from warp.geometry import IsoSurfaceMarchingCubes as _Tables

from ..mesh import NODE_CLEARANCE
from .band import band_slot, unflatten

wp.set_module_options({"enable_backward": False})

__all__ = ["Tables", "count_kernel", "faces_kernel", "tables", "vertices_kernel"]

_CLEARANCE = wp.constant(NODE_CLEARANCE)


def _edge_offsets() -> np.ndarray:
    """Per cube edge: the offset of its lower node from the cell's origin, and its axis."""
    out = []
    for c0, c1 in _Tables.EDGE_TO_CORNERS:
        p0 = np.array(_Tables.CUBE_CORNER_OFFSETS[c0])
        p1 = np.array(_Tables.CUBE_CORNER_OFFSETS[c1])
        lo = np.minimum(p0, p1)
        out.append((*lo, int(np.argmax(np.abs(p1 - p0)))))
    return np.array(out, dtype=np.int32)


@wp.struct
class Tables:
    """Marching-cubes case tables on one device."""

    tri_range: wp.array[wp.int32]
    """257 entries: the triangles of case ``c`` are ``tri_edges[tri_range[c]:tri_range[c+1]]``."""
    tri_edges: wp.array[wp.int32]
    """Cube edge (0-11) of each triangle corner."""
    edge_offsets: wp.array2d[wp.int32]
    """Per cube edge: lower node offset (3) and axis."""
    corners: wp.array2d[wp.int32]
    """Per cube corner: its offset from the cell's origin."""


_TABLES: dict[str, Tables] = {}


def tables(device: wp.context.Device) -> Tables:
    """The case tables on ``device`` (made once per device)."""
    key = str(device)
    if key not in _TABLES:
        t = Tables()
        t.tri_range = wp.array(_Tables.CASE_TO_TRI_RANGE, dtype=wp.int32, device=device)
        t.tri_edges = wp.array(_Tables.TRI_LOCAL_INDICES, dtype=wp.int32, device=device)
        t.edge_offsets = wp.array(_edge_offsets(), dtype=wp.int32, device=device)
        t.corners = wp.array(np.array(_Tables.CUBE_CORNER_OFFSETS, dtype=np.int32),
                             dtype=wp.int32, device=device)
        _TABLES[key] = t
    return _TABLES[key]


@wp.func
def _node(band: wp.array[int], count: wp.array[int], use_band: int, s: int,
          shape: wp.vec3i) -> wp.vec3i:
    """Node of thread ``s``: the band's ``s``-th entry, or the ``s``-th node in C order."""
    if use_band != 0:
        return band_slot(band, count, s, 0, shape)
    return unflatten(s, shape)


@wp.func
def _crosses(p0: float, p1: float) -> bool:
    return (p0 >= 0.0) != (p1 >= 0.0)


@wp.func
def _axis_node(n: wp.vec3i, axis: int) -> wp.vec3i:
    m = n
    m[axis] = m[axis] + 1
    return m


@wp.func
def _case(phi: wp.array3d[float], tab: Tables, n: wp.vec3i) -> int:
    """Marching-cubes case of the cell at node ``n`` (bit c: corner c has ``phi >= 0``)."""
    code = int(0)
    for c in range(8):
        if phi[n[0] + tab.corners[c, 0], n[1] + tab.corners[c, 1], n[2] + tab.corners[c, 2]] >= 0.0:
            code = code | (1 << c)
    return code


@wp.func
def _is_cell(n: wp.vec3i, shape: wp.vec3i) -> bool:
    return n[0] >= 0 and n[0] < shape[0] - 1 and n[1] < shape[1] - 1 and n[2] < shape[2] - 1


@wp.kernel
def count_kernel(
    phi: wp.array3d[float],
    tab: Tables,
    band: wp.array[int],
    count: wp.array[int],
    use_band: int,
    totals: wp.array[wp.int32],
):
    """Count the crossing edges from each node (``totals[0]``) and the triangles (``[1]``)."""
    shape = wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2])
    n = _node(band, count, use_band, wp.tid(), shape)
    if n[0] < 0:
        return
    p = phi[n[0], n[1], n[2]]
    edges = int(0)
    for axis in range(3):
        if n[axis] < shape[axis] - 1:
            m = _axis_node(n, axis)
            if _crosses(p, phi[m[0], m[1], m[2]]):
                edges = edges + 1
    if edges > 0:
        wp.atomic_add(totals, 0, edges)
    if _is_cell(n, shape):
        code = _case(phi, tab, n)
        tris = (tab.tri_range[code + 1] - tab.tri_range[code]) // 3
        if tris > 0:
            wp.atomic_add(totals, 1, tris)


@wp.kernel
def vertices_kernel(
    phi: wp.array3d[float],
    band: wp.array[int],
    count: wp.array[int],
    use_band: int,
    next_slot: wp.array[wp.int32],
    edge_slot: wp.array4d[wp.int32],
    edge_node: wp.array[wp.vec3i],
    edge_axis: wp.array[wp.int32],
    edge_t: wp.array[float],
):
    """Give each crossing edge from a node a vertex slot: node, axis and crossing ``t``."""
    shape = wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2])
    n = _node(band, count, use_band, wp.tid(), shape)
    if n[0] < 0:
        return
    p = phi[n[0], n[1], n[2]]
    for axis in range(3):
        if n[axis] < shape[axis] - 1:
            m = _axis_node(n, axis)
            q = phi[m[0], m[1], m[2]]
            if _crosses(p, q):
                slot = wp.atomic_add(next_slot, 0, 1)
                if slot < edge_t.shape[0]:
                    edge_slot[n[0], n[1], n[2], axis] = slot
                    edge_node[slot] = n
                    edge_axis[slot] = axis
                    edge_t[slot] = wp.clamp(p / (p - q), _CLEARANCE, 1.0 - _CLEARANCE)


@wp.kernel
def faces_kernel(
    phi: wp.array3d[float],
    tab: Tables,
    band: wp.array[int],
    count: wp.array[int],
    use_band: int,
    edge_slot: wp.array4d[wp.int32],
    next_face: wp.array[wp.int32],
    missing: wp.array[wp.int32],
    faces: wp.array2d[wp.int32],
):
    """Write the triangles of each cell as vertex slots, wound toward ``phi > 0``.

    A triangle corner whose edge has no slot (its node was not in the band) is counted in
    ``missing`` and the triangle is not written.
    """
    shape = wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2])
    n = _node(band, count, use_band, wp.tid(), shape)
    if n[0] < 0 or not _is_cell(n, shape):
        return
    code = _case(phi, tab, n)
    start = tab.tri_range[code]
    tris = (tab.tri_range[code + 1] - start) // 3
    for t in range(tris):
        v = wp.vec3i(0, 0, 0)
        ok = int(1)
        for c in range(3):
            e = tab.tri_edges[start + 3 * t + c]
            slot = edge_slot[n[0] + tab.edge_offsets[e, 0], n[1] + tab.edge_offsets[e, 1],
                             n[2] + tab.edge_offsets[e, 2], tab.edge_offsets[e, 3]]
            if slot < 0:
                ok = 0
            v[c] = slot
        if ok == 0:
            wp.atomic_add(missing, 0, 1)
        else:
            f = wp.atomic_add(next_face, 0, 1)
            if f < faces.shape[0]:
                faces[f, 0] = v[0]
                faces[f, 1] = v[1]
                faces[f, 2] = v[2]
