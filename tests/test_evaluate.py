"""The evaluator: exact distances, the constraint-hull crop and normal angles."""

import math

import numpy as np
import pytest
import trimesh

from warpspec.errors import InputError
from warpspec.evaluate import (
    CHAMFER_CONVENTION,
    Evaluation,
    closest_point,
    closest_point_on_triangles,
    crop_mesh,
    evaluate,
    hull_region,
    mesh_normals_at,
    ray_mesh_intersect,
    truth_region,
)
from warpspec.synthetic import make_scene


def brute_force_distance(mesh, q):
    tri = mesh.triangles
    f = len(tri)
    qi = np.repeat(np.arange(len(q)), f)
    fi = np.tile(np.arange(f), len(q))
    cp, _ = closest_point_on_triangles(q[qi], tri[fi, 0], tri[fi, 1], tri[fi, 2])
    return np.linalg.norm(cp - q[qi], axis=1).reshape(len(q), f).min(axis=1)


def square(z=0.0, size=2.0, n=8):
    g = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    v = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])
    idx = np.arange(v.shape[0]).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return trimesh.Trimesh(v, faces, process=False)


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(subdivisions=2),
                                  trimesh.creation.box(extents=(1.0, 2.0, 0.5)),
                                  trimesh.creation.cylinder(radius=0.3, height=1.5, sections=24)],
                         ids=["sphere", "box", "cylinder"])
def test_closest_point_matches_brute_force(mesh):
    rng = np.random.default_rng(0)
    q = rng.normal(size=(300, 3)) * rng.uniform(0.05, 3.0, size=(300, 1))
    cp, d, face, _ = closest_point(mesh, q)
    np.testing.assert_allclose(d, brute_force_distance(mesh, q), rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(cp - q, axis=1), d, atol=1e-14)
    # The closest point lies on the reported face (its plane).
    tri = mesh.triangles[face]
    off = np.einsum("ij,ij->i", cp - tri[:, 0], mesh.face_normals[face])
    assert np.abs(off).max() < 1e-12


def test_truth_against_itself_is_zero():
    truth = trimesh.creation.icosphere(subdivisions=4)
    e = evaluate(truth, truth, spacing=0.05, samples=5000,
                 specular_points=truth.triangles_center[::50])
    for s in (e.accuracy, e.completeness):
        assert s.max < 1e-12 and s.count > 5000
    assert e.chamfer < 1e-12 and e.hausdorff < 1e-12
    assert e.normal_angle_max < 1e-9
    d = e.to_dict()
    assert d["chamfer_convention"] == CHAMFER_CONVENTION
    assert d["accuracy_voxels"]["max"] < 1e-10
    assert "symmetric mean" in e.table() and "Chamfer" in e.table()


@pytest.mark.parametrize("delta", [0.02, -0.05])
def test_sphere_against_offset_sphere_gives_delta(delta):
    radius, h = 1.0, 0.01
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    truth = trimesh.creation.icosphere(subdivisions=4, radius=radius + delta)
    e = evaluate(mesh, truth, spacing=h, samples=5000)
    # Tessellation error of the icosphere: face planes sit within ~3e-4 R of the sphere.
    tess = 1e-3 * abs(delta) + 1e-6
    for s in (e.accuracy, e.completeness):
        assert s.mean == pytest.approx(abs(delta), abs=tess)
        assert s.max == pytest.approx(abs(delta), abs=tess)
        assert s.p95 <= s.max and s.mean <= s.rms <= s.max
    assert e.chamfer == pytest.approx(abs(delta), abs=tess)
    assert e.to_dict()["chamfer_voxels"] == pytest.approx(abs(delta) / h, abs=tess / h)


def test_parallel_planes_give_exact_offset():
    e = evaluate(square(0.0), square(0.03), samples=2000)
    assert e.accuracy.max == pytest.approx(0.03, abs=1e-15)
    assert e.accuracy.mean == pytest.approx(0.03, abs=1e-15)
    assert e.completeness.mean == pytest.approx(0.03, abs=1e-15)


def test_hull_crop_keeps_inside_and_drops_outside():
    # A tilted square of constraint points; hull = that square on its plane.
    t = math.radians(30)
    u = np.array([math.cos(t), 0.0, math.sin(t)])
    v = np.array([0.0, 1.0, 0.0])
    n = np.cross(u, v)
    o = np.array([0.2, -0.1, 0.3])
    corners = o + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [0.2, 0.3]]) @ np.stack([u, v])
    region = hull_region(corners)
    inside = o + 0.9 * u - 0.8 * v
    outside = o + 1.1 * u
    queries = np.array([inside, inside + 0.7 * n, outside, outside - 0.2 * n, o - 2 * v])
    np.testing.assert_array_equal(region.contains(queries), [True, True, False, False, False])
    assert region.contains(corners).all()
    # Margin and height limits.
    assert hull_region(corners, margin=0.15).contains(outside[None])[0]
    assert not hull_region(corners, height=0.5).contains((inside + 0.7 * n)[None])[0]
    with pytest.raises(InputError, match="collinear"):
        hull_region([[0, 0, 0], [1, 1, 1], [2, 2, 2]])


def test_crop_limits_evaluation_to_the_region():
    truth = square(0.0, size=2.0, n=20)
    mesh = square(0.0, size=2.0, n=20)
    # Push the mesh away from the truth outside the central region only.
    v = mesh.vertices.copy()
    far = np.abs(v[:, :2]).max(axis=1) > 0.6
    v[far, 2] += 0.5
    mesh = trimesh.Trimesh(v, mesh.faces, process=False)
    points = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]])
    whole = evaluate(mesh, truth, samples=3000)
    cropped = evaluate(mesh, truth, samples=3000, region=points)
    assert whole.accuracy.max > 0.4
    assert cropped.cropped and cropped.accuracy.max < 1e-12 and cropped.completeness.max < 1e-12
    kept = crop_mesh(mesh, hull_region(points))
    assert len(kept.faces) and np.all(np.abs(kept.vertices[:, :2]) <= 0.5 + 1e-12)


def test_normal_angles_measure_orientation():
    truth = trimesh.creation.icosphere(subdivisions=3)
    pts = truth.triangles_center[::20]
    normals = truth.face_normals[::20]
    same = evaluate(truth, truth, samples=1000, specular_points=pts, true_normals=normals)
    assert same.normal_angle_max < 1e-9
    flipped = trimesh.Trimesh(truth.vertices, truth.faces[:, ::-1], process=False)
    e = evaluate(flipped, truth, samples=1000, specular_points=pts, true_normals=normals)
    assert e.normal_angle_mean == pytest.approx(180.0, abs=1e-6)
    tilted = normals + 0.1 * np.cross(normals, [0.0, 0.0, 1.0])
    e = evaluate(truth, truth, samples=1000, specular_points=pts, true_normals=tilted)
    assert 0 < e.normal_angle_mean <= e.normal_angle_max < 6.0


def test_octant_truth_against_offset_sphere_cropped_to_constraints():
    s = make_scene("octant")
    truth = s.truth_mesh(subdivisions=4)
    # The far side of the closed sphere also projects into the hull: limit the height.
    region = hull_region(np.concatenate([s.truth_points, s.points]), height=0.5)
    delta = 0.03
    outer = trimesh.creation.icosphere(subdivisions=5, radius=1.0 + delta)
    e = evaluate(outer, truth, region=region, spacing=0.02, samples=4000,
                 specular_points=s.truth_points, true_normals=s.truth_normals)
    assert isinstance(e, Evaluation) and e.cropped
    assert e.completeness.mean == pytest.approx(delta, abs=2e-3)
    assert e.accuracy.mean == pytest.approx(delta, abs=2e-3)
    assert e.normal_angle_max < 2.0


def test_bad_input_raises():
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    sphere = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(InputError):
        evaluate(empty, sphere)
    with pytest.raises(InputError, match="region"):
        evaluate(sphere, sphere, region=[[5, 5, 5], [6, 5, 5], [5, 6, 5]])


def test_rays_meet_a_sphere_mesh_where_they_meet_the_sphere():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    rng = np.random.default_rng(4)
    origins = rng.normal(size=(40, 3))
    origins = 3.0 * origins / np.linalg.norm(origins, axis=1, keepdims=True)
    targets = 0.5 * rng.uniform(-1, 1, size=(40, 3))
    dirs = targets - origins
    hits, faces = ray_mesh_intersect(mesh, origins, dirs)
    assert np.all(faces >= 0)
    # The hit lies on the face it names, on the near side of the sphere.
    tri = mesh.triangles[faces]
    off = np.einsum("ij,ij->i", hits - tri[:, 0], mesh.face_normals[faces])
    assert np.abs(off).max() < 1e-12
    r = np.linalg.norm(hits, axis=1)
    assert np.all((r > 1 - 5e-4) & (r <= 1 + 1e-12))
    assert np.all(np.einsum("ij,ij->i", hits - origins, dirs) > 0)
    assert np.all(np.einsum("ij,ij->i", hits, origins) > 0)
    # A ray that points away misses; one that starts inside meets the far side.
    hits, faces = ray_mesh_intersect(mesh, [[3.0, 0, 0], [0, 0, 0]], [[1.0, 0, 0], [0, 0, 1.0]])
    assert faces[0] == -1 and np.all(np.isnan(hits[0]))
    assert hits[1] == pytest.approx([0, 0, 1], abs=1e-12)


def test_vertex_normals_smooth_the_facets():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(1)
    q = rng.normal(size=(200, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    face = mesh_normals_at(sphere, q)
    vertex = mesh_normals_at(sphere, q, mode="vertex")
    np.testing.assert_allclose(np.linalg.norm(vertex, axis=1), 1.0, atol=1e-12)
    err_face = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", face, q), -1, 1)))
    err_vertex = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", vertex, q), -1, 1)))
    assert err_vertex.mean() < 0.5 * err_face.mean()
    with pytest.raises(InputError, match="mode"):
        mesh_normals_at(sphere, q, mode="phong")


def test_truth_region_ignores_missing_points():
    pts = np.array([[0, 0, 0], [1, 0, 0], [np.nan, np.nan, np.nan]])
    region = truth_region(pts, [[0, 1, 0]])
    assert region.contains(np.array([[0.2, 0.2, 0.0], [0.9, 0.9, 0.0]])).tolist() == [True, False]
