"""Surface extraction: marching cubes on the level set, faces outward, in world units."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .errors import ReconstructionError
from .grid import Grid

if TYPE_CHECKING:  # trimesh and scikit-image load in ~1 s: only when a mesh is made
    import trimesh

__all__ = ["crop_to_hull", "extract_mesh", "sample_trilinear"]


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


def extract_mesh(phi: np.ndarray, grid: Grid) -> trimesh.Trimesh:
    """Triangulate the zero set of ``phi`` with faces facing ``phi > 0``.

    scikit-image's winding depends on its ``gradient_direction``; rather than trust it, the
    winding is checked against ``phi`` itself: stepping along the face normals must increase
    ``phi`` on most faces, else every face is flipped. Normals come from the mesh.

    Raises:
        ReconstructionError: If ``phi`` has no zero crossing inside the grid.
    """
    import trimesh
    from skimage import measure

    phi = np.asarray(phi, dtype=np.float32)
    if not (phi.min() < 0.0 < phi.max()):
        raise ReconstructionError(
            "the zero set of phi does not cross the domain: there is no surface to mesh "
            f"(phi ranges over [{phi.min():.3g}, {phi.max():.3g}])"
        )
    h = grid.spacing
    verts, faces, _, _ = measure.marching_cubes(phi, level=0.0, spacing=(h, h, h))
    verts = verts.astype(np.float64) + grid.origin
    mesh = trimesh.Trimesh(vertices=verts, faces=faces, process=True)
    if len(mesh.faces):
        centres = mesh.triangles_center
        step = 0.25 * h * mesh.face_normals
        rise = sample_trilinear(phi, grid, centres + step) - sample_trilinear(phi, grid,
                                                                                centres - step)
        if np.sum(np.sign(rise) * mesh.area_faces) < 0:
            mesh.invert()
    return mesh


def crop_to_hull(mesh: trimesh.Trimesh, anchors: np.ndarray) -> trimesh.Trimesh:
    """Keep the faces whose centres fall inside the hull of ``anchors`` (the paper's figures).

    The anchors (ray intersections and point constraints) are projected onto their best-fit
    plane, and a face is kept when its centre's projection lies in their 2-D convex hull.

    Raises:
        ReconstructionError: If fewer than three anchors span a plane, or nothing is inside.
    """
    from .evaluate import hull_region

    keep = hull_region(np.asarray(anchors, dtype=np.float64)).contains(mesh.triangles_center)
    if not np.any(keep):
        raise ReconstructionError("crop: no face of the mesh lies inside the constraints' hull")
    out = mesh.copy()
    out.update_faces(keep)
    out.remove_unreferenced_vertices()
    return out
