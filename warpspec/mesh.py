"""Surface extraction: marching cubes on the level set, faces outward, in world units."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from .errors import ReconstructionError
from .grid import Grid

if TYPE_CHECKING:  # trimesh (and SciPy) load in ~0.6 s: only when a Trimesh is asked for
    import trimesh
    import warp as wp

__all__ = [
    "crop_to_support",
    "extract_mesh",
    "faces_behind",
    "sample_trilinear",
    "supported_components",
    "triangulate",
    "triangulate_device",
    "vertex_components",
    "write_ply",
]


def sample_trilinear(field: np.ndarray, grid: Grid, points: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of a nodal field at world points (clamped to the grid)."""
    q = grid.to_index(points)
    upper = np.asarray(field.shape) - 1
    q = np.clip(q, 0, upper)
    base = np.minimum(np.floor(q).astype(np.int64), upper - 1)
    f = q - base
    out = np.zeros(len(q))
    for corner in range(8):
        offset = np.array([(corner >> a) & 1 for a in range(3)])
        w = np.prod(np.where(offset == 1, f, 1.0 - f), axis=1)
        idx = base + offset
        out += w * field[idx[:, 0], idx[:, 1], idx[:, 2]]
    return out


NODE_CLEARANCE = 1e-3
"""Least distance of a vertex from a grid node, in edge lengths. Where ``phi`` at a node is
nearly zero (2.5e-9 beside a bottle's shoulder) the crossings of its six edges fall within
1e-7 voxel of it and of each other; merged by position (as a mesh file's reader does) they
closed two faces on each other, a speck that changed the open tube's Euler number. Held a
thousandth of an edge off the nodes they stay apart; the surface moves by at most that."""


def triangulate(phi: np.ndarray, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the zero set of ``phi``: vertices (world, float64) and faces facing ``phi > 0``.

    Marching cubes (scikit-image); vertices at the same position are merged, compared in grid
    units (to 1e-6 of a voxel, whatever the scene's units: the result does not depend on
    them). scikit-image's winding depends on its ``gradient_direction``; rather
    than trust it, the winding is checked against ``phi`` itself: stepping along the face
    normals must increase ``phi`` on most of the area, else every face is flipped. NumPy and
    scikit-image only: importing trimesh costs more than the whole triangulation.

    Raises:
        ReconstructionError: If ``phi`` has no zero crossing inside the grid.
    """
    from skimage import measure

    phi = np.asarray(phi, dtype=np.float32)
    if not (phi.min() < 0.0 < phi.max()):
        raise ReconstructionError(
            "the zero set of phi does not cross the domain: there is no surface to mesh "
            f"(phi ranges over [{phi.min():.3g}, {phi.max():.3g}])"
        )
    h = grid.spacing
    # nodes where phi is nearly (not exactly) zero held off the zero set, as the device's
    # vertices are held off the nodes (NODE_CLEARANCE): the crossings around them stay apart.
    # A node exactly on it gives its edges one vertex there, which the merge below shares.
    clear = np.float32(NODE_CLEARANCE * h)
    tiny = (phi != 0.0) & (np.abs(phi) < clear)
    phi = np.where(tiny, np.where(phi < 0.0, -clear, clear), phi)
    verts, faces, _, _ = measure.marching_cubes(phi, level=0.0)  # grid units
    # Keys in millionths of a voxel: any grid Warp can index (< 2^31 nodes) fits in int64.
    key = np.round(verts.astype(np.float64) * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the vertices in the order they first appear
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    verts = verts[first[order]].astype(np.float64) * h + grid.origin
    faces = rank[inverse.reshape(-1)][faces].astype(np.int64)
    if len(faces):
        tri = verts[faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        normal = cross / np.maximum(2.0 * area, 1e-300)[:, None]
        centres = tri.mean(axis=1)
        step = 0.25 * h * normal
        rise = sample_trilinear(phi, grid, centres + step) - sample_trilinear(phi, grid,
                                                                              centres - step)
        if np.sum(np.sign(rise) * area) < 0:
            faces = faces[:, ::-1].copy()
    return verts, faces


def triangulate_device(
    phi: wp.array,
    grid: Grid,
    *,
    band: wp.array | None = None,
    count: wp.array | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the zero set of a device level set with marching cubes run on its device.

    The same surface as :func:`triangulate` (vertices at the linear zero crossings of the grid
    edges, faces toward ``phi > 0``) without copying the grid to the host: one vertex per
    crossing edge, shared by the faces around it (no merging by position), so a closed
    surface comes out watertight. With ``band`` only the cells whose origin node is in the
    band are visited; the band must hold every node within one cell of the zero set (a
    narrow band of 2 voxel widths or more around a distance function does).

    Args:
        phi: Level set, float32 ``wp.array3d`` of ``grid.shape`` on any device.
        grid: Its grid (origin, spacing).
        band: Optional narrow band, as :func:`~warpspec.kernels.band.build_band`
            encodes it (on the same device); ``count`` must come with it.
        count: One int on the device: how many entries of ``band`` are valid.

    Returns:
        Vertices (world, float64, shape ``(V, 3)``) and faces (int64, shape ``(F, 3)``).

    Raises:
        ReconstructionError: If there is no zero crossing, or the band misses a node of a
            cell that the surface crosses.
        InputError: If ``phi`` does not match ``grid`` or ``band`` comes without ``count``.
    """
    import warp as wp

    from .errors import InputError
    from .kernels import marching

    if not isinstance(phi, wp.array) or phi.ndim != 3 or phi.dtype != wp.float32:
        raise InputError("phi: must be a float32 wp.array3d; for NumPy use triangulate()")
    if tuple(phi.shape) != tuple(grid.shape):
        raise InputError(f"phi: shape {tuple(phi.shape)} does not match the grid {grid.shape}")
    if (band is None) != (count is None):
        raise InputError("band: band and count must be given together")
    device = phi.device
    use_band = 0 if band is None else 1
    if band is None:
        band = wp.empty(0, dtype=int, device=device)
        count = wp.zeros(1, dtype=int, device=device)
        threads = grid.size
    else:
        threads = int(band.shape[0])
    tab = marching.tables(device)
    totals = wp.zeros(2, dtype=wp.int32, device=device)
    common = [band, count, use_band]
    wp.launch(marching.count_kernel, dim=threads, inputs=[phi, tab, *common],
              outputs=[totals], device=device)
    n_edges, n_faces = (int(v) for v in totals.numpy())
    if n_faces == 0:
        raise ReconstructionError("the zero set of phi does not cross the domain: there is no "
                                  "surface to mesh")
    edge_slot = wp.full((*grid.shape, 3), -1, dtype=wp.int32, device=device)
    edge_node = wp.empty(n_edges, dtype=wp.vec3i, device=device)
    edge_axis = wp.empty(n_edges, dtype=wp.int32, device=device)
    edge_t = wp.empty(n_edges, dtype=float, device=device)
    totals.zero_()
    wp.launch(marching.vertices_kernel, dim=threads, inputs=[phi, *common, totals],
              outputs=[edge_slot, edge_node, edge_axis, edge_t], device=device)
    faces = wp.empty((n_faces, 3), dtype=wp.int32, device=device)
    missing = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(marching.faces_kernel, dim=threads,
              inputs=[phi, tab, *common, edge_slot, totals[1:], missing],
              outputs=[faces], device=device)
    lost = int(missing.numpy()[0])
    if lost:
        raise ReconstructionError(
            f"band: {lost} triangles cross edges whose nodes are not in the band; widen the "
            "band to at least 2 voxel widths"
        )
    # world positions in float64 on the host: O(surface), exact to the float32 crossing
    node = edge_node.numpy().astype(np.float64)
    node[np.arange(n_edges), edge_axis.numpy()] += edge_t.numpy()
    verts = grid.origin + grid.spacing * node
    return verts, faces.numpy().astype(np.int64)


def extract_mesh(phi: np.ndarray, grid: Grid) -> trimesh.Trimesh:
    """The zero set of ``phi`` as a ``trimesh.Trimesh``, faces facing ``phi > 0``.

    See :func:`triangulate`.

    Raises:
        ReconstructionError: If ``phi`` has no zero crossing inside the grid.
    """
    import trimesh

    verts, faces = triangulate(phi, grid)
    return trimesh.Trimesh(vertices=verts, faces=faces, process=False)


PLY_FLOAT_TOLERANCE = 1e-6
"""Largest float32 rounding of a vertex, as a fraction of the mesh's longest side, that a PLY
file's ``float`` coordinates may carry (64 voxels wide: 6e-5 of a voxel)."""


def _float32_holds(vertices: np.ndarray) -> bool:
    """Whether float32 keeps every vertex within :data:`PLY_FLOAT_TOLERANCE` of the mesh's size."""
    if not len(vertices):
        return True
    with np.errstate(over="ignore", invalid="ignore"):
        moved = np.max(np.abs(vertices.astype(np.float32).astype(np.float64) - vertices))
    size = float(np.max(np.ptp(vertices, axis=0)))
    return bool(moved <= PLY_FLOAT_TOLERANCE * size)


def write_ply(
    path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, *,
    vertex_properties: dict[str, np.ndarray] | None = None,
) -> None:
    """Write a triangle mesh as binary little-endian PLY (float vertices, int indices).

    The layout is the one trimesh writes; the command line uses it for ``.ply`` so that a run
    need not import trimesh at all. Coordinates are ``double`` instead of ``float`` where
    float32 would move a vertex by more than :data:`PLY_FLOAT_TOLERANCE` of the mesh's size
    (a scene in a geographic frame, millions of units from its origin).

    Args:
        path: The file to write (overwritten; callers write through a temporary file).
        vertices: ``(n, 3)`` positions.
        faces: ``(m, 3)`` vertex indices.
        vertex_properties: Extra per-vertex float properties (name -> ``(n,)`` array), such
            as ``support``; written after ``x, y, z`` as ``float``.
    """
    extra = dict(vertex_properties or {})
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    coordinate = "float" if _float32_holds(vertices) else "double"
    layout = ([("xyz", "<f4" if coordinate == "float" else "<f8", (3,))]
              + [(name, "<f4") for name in extra])
    table = np.empty(len(vertices), dtype=layout)
    table["xyz"] = vertices
    for name, values in extra.items():
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if len(values) != len(vertices):
            raise ValueError(f"vertex property {name!r}: {len(values)} values for "
                             f"{len(vertices)} vertices")
        with np.errstate(over="ignore"):
            table[name] = np.minimum(values, np.finfo(np.float32).max)
    faces = np.asarray(faces)
    records = np.empty(len(faces), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    records["count"] = 3
    records["index"] = faces
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(vertices)}\n"
        + "".join(f"property {coordinate} {axis}\n" for axis in "xyz")
        + "".join(f"property float {name}\n" for name in extra)
        + f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(table.tobytes())
        f.write(records.tobytes())


def crop_to_support(
    vertices: np.ndarray, faces: np.ndarray, support: np.ndarray, limit: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep the faces whose three vertices lie within ``limit`` voxels of a constraint.

    Returns:
        The kept vertices, faces (re-indexed) and the vertices' support distances.

    Raises:
        ReconstructionError: If no face is kept.
    """
    faces = np.asarray(faces)
    near = np.asarray(support) <= limit
    keep = np.all(near[faces], axis=1) if len(faces) else np.zeros(0, dtype=bool)
    if not np.any(keep):
        raise ReconstructionError(f"crop: no face of the mesh lies within {limit:g} voxels of "
                                  "a constraint")
    faces = faces[keep]
    used = np.unique(faces)
    index = np.full(len(vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return np.asarray(vertices)[used], index[faces], np.asarray(support)[used]


def vertex_components(n: int, faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Label the connected pieces of a triangle mesh.

    Vertices joined by an edge share a label; a vertex no face uses is a piece of its own.
    Each round hooks the root of every edge's larger label under the smaller one and then
    flattens the pointers (pointer jumping), so a mesh of ``n`` vertices takes a few rounds
    of array operations, with no graph library to load: a one-piece mesh, the common case,
    costs milliseconds.

    Args:
        n: The number of vertices.
        faces: ``(F, 3)`` vertex indices.

    Returns:
        The number of pieces and, per vertex, its piece (``0 .. count - 1``, in the order of
        each piece's lowest vertex index).
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    u = faces.ravel()
    v = faces[:, [1, 2, 0]].ravel()
    root = np.arange(n, dtype=np.int64)
    while True:
        a, b = root[u], root[v]
        differ = a != b
        if not differ.any():
            break
        a, b = a[differ], b[differ]
        low = np.minimum(a, b)
        np.minimum.at(root, np.maximum(a, b), low)
        while True:
            jumped = root[root]
            if np.array_equal(jumped, root):
                break
            root = jumped
    _, label = np.unique(root, return_inverse=True)
    return int(label.max()) + 1 if n else 0, label.reshape(-1)


def supported_components(vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray,
                         *, radius: float, min_extent: float = 0.0
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Drop the connected pieces of a mesh that come nowhere near the data, and specks.

    A smooth fit extrapolates beyond the constraints, and far from them its zero set may close
    into pieces that no ray or point speaks for (a second sheet of a saddle, a blob in a
    corner). A piece is kept when one of its vertices lies within ``radius`` of an anchor (a ray
    intersection or a point constraint); with no anchors the mesh is returned unchanged. A
    piece whose bounding box has a diagonal shorter than ``min_extent`` is dropped wherever it
    lies: a bubble of the level set a voxel across, pinched off beside the data, is no
    surface the grid resolves, and it would make a closed object two pieces and change its
    Euler number. The largest piece is never dropped for its size.

    Returns:
        The kept vertices (in their order) and faces (renumbered).
    """
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 3)
    if len(faces) == 0 or len(anchors) == 0:
        return vertices, faces
    count, label = vertex_components(len(vertices), faces)
    if count == 1:
        return vertices, faces
    from scipy.spatial import cKDTree

    near, _ = cKDTree(anchors).query(vertices, distance_upper_bound=radius)
    supported = np.zeros(count, dtype=bool)
    supported[np.unique(label[np.isfinite(near)])] = True
    if min_extent > 0.0:
        lo = np.full((count, 3), np.inf)
        hi = np.full((count, 3), -np.inf)
        np.minimum.at(lo, label, vertices)
        np.maximum.at(hi, label, vertices)
        extent = np.linalg.norm(hi - lo, axis=1)
        supported &= (extent >= min_extent) | (extent == extent.max())
    if supported.all() or not supported.any():
        return vertices, faces
    keep_vertex = supported[label]
    new_index = np.cumsum(keep_vertex) - 1
    keep_face = keep_vertex[faces[:, 0]]
    return vertices[keep_vertex], new_index[faces[keep_face]]


FACING_CHUNK = 1 << 22
"""Face-viewpoint pairs tested at once by :func:`faces_behind` (32 MiB of float64)."""


def faces_behind(vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray, *,
                 radius: float, front: np.ndarray, viewpoints: np.ndarray | None = None,
                 seen: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The faces behind the data: turned away from its front, and in pieces far from it.

    A face (normal ``n``, centre ``x``) is turned away when ``n . front <= 0``, or, with
    ``viewpoints``, when no viewpoint ``c`` looks at its front side (``n . (c - x) <= 0`` for
    every one). The faces turned away are grouped into connected pieces, and a piece is
    behind the data when none of its vertices lies within ``radius`` of an anchor (a ray's
    hit or a point). A piece that reaches the data is kept whole: a slope between two
    highlights that the cameras see edge-on is part of what they saw.

    Args:
        vertices: ``(V, 3)`` vertex positions.
        faces: ``(F, 3)`` vertex indices.
        anchors: ``(A, 3)`` constraint positions.
        radius: Distance within which a piece reaches the data.
        front: The direction the data's side faces.
        viewpoints: ``(C, 3)`` camera centres.
        seen: Hits ``(K, 3)`` and the centres of the cameras that saw them ``(K, 3)``: the
            normals' sense is the one the faces nearest the hits turn to those cameras (the
            majority). Without it, the windings' own.

    Returns:
        A boolean mask over the faces, ``True`` where a face lies behind the data.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 3)
    behind = np.zeros(len(faces), dtype=bool)
    if len(faces) == 0 or len(anchors) == 0:
        return behind
    from scipy.spatial import cKDTree

    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if seen is not None and len(seen[0]):
        hits, cameras = (np.asarray(a, dtype=np.float64).reshape(-1, 3) for a in seen)
        _, nearest = cKDTree(tri.mean(axis=1)).query(hits)
        if np.sum(np.sign(np.einsum("ij,ij->i", normal[nearest], cameras - hits))) < 0:
            normal = -normal
    away = normal @ np.asarray(front, dtype=np.float64).reshape(3) <= 0.0
    if viewpoints is not None and len(viewpoints):
        viewpoints = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3)
        level = np.einsum("ij,ij->i", normal, tri.mean(axis=1))
        step = max(1, FACING_CHUNK // len(viewpoints))  # bounded memory: faces x viewpoints
        for k in range(0, len(faces), step):
            away[k:k + step] |= (np.max(normal[k:k + step] @ viewpoints.T, axis=1)
                                 <= level[k:k + step])
    if not away.any():
        return behind
    count, label = vertex_components(len(vertices), faces[away])
    near, _ = cKDTree(anchors).query(vertices, distance_upper_bound=radius)
    used = np.zeros(len(vertices), dtype=bool)
    used[faces[away].ravel()] = True
    reaches = np.zeros(count, dtype=bool)
    reaches[np.unique(label[used & np.isfinite(near)])] = True
    behind[away] = ~reaches[label[faces[away][:, 0]]]
    return behind


def is_open(faces: np.ndarray) -> bool:
    """Whether a triangle mesh has a border (an edge used by one face only)."""
    faces = np.asarray(faces)
    if len(faces) == 0:
        return False
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1).astype(np.int64)
    keys = edges[:, 0] * (int(faces.max()) + 1) + edges[:, 1]
    _, counts = np.unique(keys, return_counts=True)
    return bool(np.any(counts == 1))
