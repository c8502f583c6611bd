"""Marching cubes on the device (mesh.triangulate_device) against mesh.triangulate."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from scipy.spatial import cKDTree

from tests.helpers import cube_grid, sphere_sdf
from warpspec.errors import InputError, ReconstructionError
from warpspec.kernels.band import launch_build_band
from warpspec.mesh import NODE_CLEARANCE, triangulate, triangulate_device


def _volume(verts: np.ndarray, faces: np.ndarray) -> float:
    tri = verts[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def _area(verts: np.ndarray, faces: np.ndarray) -> float:
    tri = verts[faces]
    return float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                axis=1).sum() / 2.0)


def _edges_used_twice(faces: np.ndarray) -> bool:
    """Closed and consistently wound: every directed edge once, its reverse once."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = set(map(tuple, directed))
    return len(keys) == len(directed) and all((b, a) in keys for a, b in keys)


def _sphere(n: int, radius: float = 0.61):
    grid = cube_grid(n)
    phi = sphere_sdf(grid, [0.03, -0.05, 0.02], radius).astype(np.float32)
    return grid, phi, radius


@pytest.mark.parametrize("use_band", [False, True])
def test_sphere_matches_triangulate_and_is_closed_outward(device, use_band):
    grid, phi, radius = _sphere(40)
    h = grid.spacing
    field = wp.array(phi, dtype=float, device=device)
    kwargs = {}
    if use_band:
        band = wp.zeros(grid.size, dtype=int, device=device)
        count = wp.zeros(1, dtype=int, device=device)
        launch_build_band(field, band, count, width=2.0 * h)
        assert 0 < int(count.numpy()[0]) < grid.size // 4
        kwargs = {"band": band, "count": count}
    verts, faces = triangulate_device(field, grid, **kwargs)
    ref_verts, ref_faces = triangulate(phi, grid)
    # the same vertices (one per crossing edge) and as many faces, no sphere node being 0
    assert len(verts) == len(ref_verts) and len(faces) == len(ref_faces)
    dist, _ = cKDTree(ref_verts).query(verts)
    assert dist.max() < 1e-5 * h
    dist, _ = cKDTree(verts).query(ref_verts)
    assert dist.max() < 1e-5 * h
    # on the sphere: the linear crossings of a distance lie within a few percent of h
    assert np.abs(np.linalg.norm(verts - [0.03, -0.05, 0.02], axis=1) - radius).max() < 0.05 * h
    # watertight, outward (positive volume, close to the sphere's)
    assert _edges_used_twice(faces)
    volume = _volume(verts, faces)
    assert volume == pytest.approx(4.0 / 3.0 * np.pi * radius**3, rel=0.01)
    # the same enclosed volume and area as scikit-image's mesh (1e-9 relative measured;
    # a face missing or wound the other way changes them by over 1e-5)
    ref_volume = _volume(ref_verts, ref_faces)
    assert abs(volume - ref_volume) < 1e-7 * ref_volume
    assert abs(_area(verts, faces) - _area(ref_verts, ref_faces)) < 1e-7 * _area(verts, faces)


def test_open_surface_faces_phi_positive(device):
    grid = cube_grid(16)
    n = np.array([0.3, -0.4, 0.866])
    n /= np.linalg.norm(n)
    idx = np.stack(np.meshgrid(*[np.arange(s) for s in grid.shape], indexing="ij"), axis=-1)
    xyz = grid.origin + grid.spacing * idx
    phi = (xyz @ n - 0.1).astype(np.float32)
    verts, faces = triangulate_device(wp.array(phi, dtype=float, device=device), grid)
    tri = verts[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # every face on the plane (to the vertices' clearance of the nodes), wound toward phi > 0
    np.testing.assert_allclose(verts @ n, 0.1, atol=NODE_CLEARANCE * grid.spacing + 1e-6)
    assert np.all(normals @ n > 0)
    ref_verts, ref_faces = triangulate(phi, grid)
    assert len(faces) == len(ref_faces) and len(verts) == len(ref_verts)


def test_errors(device):
    grid, phi, _ = _sphere(12)
    with pytest.raises(ReconstructionError, match="no surface"):
        triangulate_device(wp.array(np.abs(phi) + 1, dtype=float, device=device), grid)
    with pytest.raises(InputError, match=r"^phi: "):
        triangulate_device(wp.zeros((4, 4, 4), dtype=float, device=device), grid)
    field = wp.array(phi, dtype=float, device=device)
    band = wp.zeros(grid.size, dtype=int, device=device)
    count = wp.zeros(1, dtype=int, device=device)
    with pytest.raises(InputError, match=r"^band: "):
        triangulate_device(field, grid, band=band)
    # a band that stops short of the surface's cells
    launch_build_band(field, band, count, width=0.3 * grid.spacing)
    with pytest.raises(ReconstructionError, match=r"^band: .* widen"):
        triangulate_device(field, grid, band=band, count=count)


@pytest.mark.parametrize("host", [False, True])
def test_nodes_nearly_on_the_surface_leave_no_speck_once_positions_are_merged(device, host):
    """Where phi at a node is nearly zero the crossings of its edges fall within 1e-7 voxel
    of it: a reader merging positions (trimesh, within 1e-8) closed faces on each other. Held
    off the nodes by NODE_CLEARANCE they stay apart, and the merged mesh is the sphere:
    watertight, Euler number 2, one piece."""
    import trimesh

    grid, phi, radius = _sphere(40)
    near = np.argsort(np.abs(phi).ravel())[:12]  # the nodes nearest the sphere
    phi.ravel()[near] = np.resize(np.float32([-2.5e-9, 1e-9, -1e-12]), len(near))
    if host:
        verts, faces = triangulate(phi, grid)
    else:
        verts, faces = triangulate_device(wp.array(phi, dtype=float, device=device), grid)
    mesh = trimesh.Trimesh(verts, faces)  # merges vertices by position
    assert len(mesh.vertices) == len(verts)
    assert mesh.is_watertight and mesh.euler_number == 2
    assert len(mesh.split(only_watertight=False)) == 1
    assert np.abs(np.linalg.norm(verts - [0.03, -0.05, 0.02], axis=1) - radius).max() \
        < 0.05 * grid.spacing


@pytest.mark.parametrize("offset", [0.0, 1.0e7])
def test_ply_coordinates_are_double_only_where_float_would_round_them(tmp_path, offset):
    import trimesh

    from warpspec.mesh import write_ply

    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    vertices = box.vertices + offset
    write_ply(tmp_path / "m.ply", vertices, box.faces,
              vertex_properties={"support": np.zeros(len(vertices))})
    header = (tmp_path / "m.ply").read_bytes().split(b"end_header")[0].decode()
    assert ("property double x" in header) == (offset > 0)
    assert "property float support" in header
    back = trimesh.load(tmp_path / "m.ply", process=False)
    np.testing.assert_allclose(back.vertices, vertices, rtol=0, atol=1e-7 * 0.3)
