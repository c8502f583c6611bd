"""The synthetic scene generator: the reflection law holds exactly at the true points."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from warpspec.errors import SceneError
from warpspec.synthetic import (
    Blob,
    CameraLight,
    Cylinder,
    DirectionalLight,
    Ellipsoid,
    FreeformHeightField,
    Halfspace,
    Intrinsics,
    MeshSurface,
    Paraboloid,
    Plane,
    PointLight,
    Revolution,
    Saddle,
    Sphere,
    Torus,
    clip_mesh,
    find_highlight,
    jitter_points,
    look_at,
    make_scene,
    place_camera,
    project,
    scene_from_path,
    scene_from_points,
    scene_names,
)

SHAPES = ["sphere-around", "ellipsoid-around", "pebble", "torus", "torus-lamps", "torus-point",
          "blob", "bottle", "bottle-lamps", "wrap", "freeform", "point-light"]
CLOSED = {"sphere-around": 2, "ellipsoid-around": 2, "pebble": 2, "torus": 0, "torus-lamps": 0,
          "torus-point": 0, "blob": 2}

NAMES = scene_names()
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


@pytest.fixture(scope="module")
def scenes():
    return {name: make_scene(name) for name in NAMES}


def design_ray(P, pixel):
    """DESIGN section 2, written out: c = -M^-1 p4, r = normalize(sign(det M) M^-1 q)."""
    P = np.asarray(P, dtype=float)
    M, p4 = P[:, :3], P[:, 3]
    c = -np.linalg.inv(M) @ p4
    r = np.sign(np.linalg.det(M)) * np.linalg.inv(M) @ np.array([pixel[0], pixel[1], 1.0])
    return c, r / np.linalg.norm(r)


def light_vector(light, x, c):
    """The unit vector L from x toward the light of a scene-file light dict."""
    if light["type"] == "directional":
        L = np.asarray(light["direction"], dtype=float)
    elif light["type"] == "point":
        L = np.asarray(light["position"], dtype=float) - x
    else:
        L = c - x
    return L / np.linalg.norm(L)


def check_reflection_law(scene_dict, truth_points, truth_normals, tol=1e-9):
    for spec, x, n in zip(scene_dict["specularities"], truth_points, truth_normals, strict=True):
        camera = scene_dict["cameras"][spec["camera"]]
        light = camera.get("light", scene_dict.get("light"))
        c, r = design_ray(camera["P"], spec["pixel"])
        # The ray passes through the true point, in front of the camera.
        depth = np.dot(x - c, r)
        assert depth > 0
        assert np.linalg.norm(np.cross(x - c, r)) < tol * np.linalg.norm(x - c)
        # The reflection law gives the true normal.
        N = light_vector(light, x, c) - r
        N /= np.linalg.norm(N)
        assert np.abs(N - n).max() < tol


@pytest.mark.parametrize("name", NAMES)
def test_reflection_law_holds_at_true_points(scenes, name):
    s = scenes[name]
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)
    np.testing.assert_allclose(np.linalg.norm(s.truth_normals, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_reflection_law_through_scene_loader(scenes, name):
    scene_mod = pytest.importorskip("warpspec.scene")
    s = scenes[name]
    try:
        loaded = s.scene()
    except (AttributeError, NotImplementedError) as exc:  # loader still being written
        pytest.skip(f"Scene.from_dict not ready: {exc}")
    assert isinstance(loaded, scene_mod.Scene)
    origins, dirs = loaded.rays()
    x = s.truth_points
    assert np.all(np.einsum("ij,ij->i", x - origins, dirs) > 0)
    miss = np.linalg.norm(np.cross(x - origins, dirs), axis=1)
    assert np.all(miss < 1e-9 * np.linalg.norm(x - origins, axis=1))
    np.testing.assert_allclose(loaded.normals(points=x), s.truth_normals, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_highlights_in_image_and_visible(scenes, name):
    s = scenes[name]
    assert np.all(s.intrinsics.contains(s.pixels))
    for i, (x, n) in enumerate(zip(s.truth_points, s.truth_normals, strict=True)):
        cam = s.camera_indices[i]
        P = s.cameras[cam]
        q, depth = project(P, x[None])
        np.testing.assert_allclose(q[0], s.pixels[i], atol=1e-9)
        assert depth[0] > 0
        c = s.camera_centres[cam]
        # The point faces the camera and the light.
        assert np.dot(c - x, n) > 0
        assert np.dot(s.light_directions[i], n) > 0
        # The first hit of the ray from the camera is the point itself.
        d = (x - c) / np.linalg.norm(x - c)
        t = s.surface.intersect(c[None], d[None])[0]
        assert abs(t - np.linalg.norm(x - c)) < 1e-9 * np.linalg.norm(x - c)


@pytest.mark.parametrize("name", NAMES)
def test_domain_is_cut_by_the_surface_and_holds_no_camera(scenes, name):
    s = scenes[name]
    lo, hi = s.domain
    g = [np.linspace(lo[k], hi[k], 9) for k in range(3)]
    nodes = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    phi = s.surface.implicit(nodes)
    assert np.any(phi < 0) and np.any(phi > 0)
    inside = lambda p: np.all((p >= lo) & (p <= hi), axis=-1)  # noqa: E731
    assert not np.any(inside(s.camera_centres))
    assert np.all(inside(s.points)) and np.all(inside(s.truth_points))
    # Cameras on the outer side; point constraints on the surface.
    assert np.all(s.surface.implicit(s.camera_centres) > 0)
    assert np.abs(s.surface.signed_distance(s.points)).max() < 1e-12


def test_builtin_scene_counts(scenes):
    counts = {
        name: (len(s.truth_points), len(s.cameras), len(s.points),
               s.scene_dict.get("light", {}).get("type"))
        for name, s in scenes.items()
    }
    assert counts["octant"] == (24, 24, 3, "directional")
    assert counts["car-window"] == (38, 38, 2, "directional")
    assert counts["wine-bottle"] == (11, 11, 4, "camera")
    assert counts["ellipsoid-cap"][3] == "point"
    np.testing.assert_array_equal(scenes["octant"].points, np.eye(3))


def test_octant_points_spread_away_from_the_rim(scenes):
    x = scenes["octant"].truth_points
    assert x.min() >= math.sin(math.radians(6.0)) - 1e-12
    d = np.linalg.norm(x[:, None] - x[None], axis=2) + np.eye(len(x)) * 9
    assert d.min() > 0.15  # well spread: no two highlights close together
    np.testing.assert_allclose(np.linalg.norm(x, axis=1), 1.0, atol=1e-14)


@pytest.mark.parametrize("name", NAMES)
def test_truth_mesh_lies_on_the_surface_and_faces_outward(scenes, name):
    s = scenes[name]
    m = s.truth_mesh()
    assert len(m.faces) > 100
    centres = m.triangles_center
    dots = np.einsum("ij,ij->i", m.face_normals, s.surface.normal(centres))
    assert dots.min() > 0.9
    # Vertices on the surface up to the cut along the patch planes.
    assert np.abs(s.surface.signed_distance(m.vertices)).max() < 1e-2
    # The specular points lie on the patch the mesh covers.
    for hs in s.patch:
        assert np.all(hs.contains(s.truth_points))


def test_truth_mesh_areas():
    assert make_scene("octant").truth_mesh().area == pytest.approx(math.pi / 2, rel=2e-3)
    assert make_scene("car-window").truth_mesh().area == pytest.approx(0.6, rel=1e-3)
    assert make_scene("wine-bottle").truth_mesh().area == pytest.approx(
        0.04 * math.pi / 2 * 0.08, rel=1e-3)


def test_same_seed_same_scene_different_seed_different():
    a = make_scene("octant", noise=0.5, outliers=0.25, seed=3)
    b = make_scene("octant", noise=0.5, outliers=0.25, seed=3)
    c = make_scene("octant", noise=0.5, outliers=0.25, seed=4)
    assert a.scene_dict == b.scene_dict
    np.testing.assert_array_equal(a.outlier_mask, b.outlier_mask)
    assert a.scene_dict != c.scene_dict
    # The geometry does not depend on the seed.
    np.testing.assert_array_equal(a.truth_points, c.truth_points)
    assert a.scene_dict["cameras"] == c.scene_dict["cameras"]


def test_noise_and_outliers():
    clean = make_scene("car-window")
    noisy = make_scene("car-window", noise=0.5, seed=1)
    np.testing.assert_array_equal(clean.pixels, clean.clean_pixels)
    dev = noisy.pixels - noisy.clean_pixels
    assert 0.3 < dev.std() < 0.7
    assert not np.any(noisy.outlier_mask)

    bad = make_scene("car-window", outliers=0.25, seed=2)
    assert bad.outlier_mask.sum() == round(0.25 * 38)
    moved = np.linalg.norm(bad.pixels - bad.clean_pixels, axis=1) > 0
    np.testing.assert_array_equal(moved, bad.outlier_mask)
    assert np.all(bad.intrinsics.contains(bad.pixels))
    # Inliers keep the law exactly.
    keep = bad.inliers
    specs = [sp for sp, k in zip(bad.scene_dict["specularities"], keep, strict=True) if k]
    check_reflection_law({**bad.scene_dict, "specularities": specs},
                         bad.truth_points[keep], bad.truth_normals[keep])


def test_point_noise_has_the_asked_spread_in_voxels_and_leaves_the_highlights():
    clean = make_scene("torus")
    voxel = float(np.max(clean.domain[1] - clean.domain[0])) / 64
    devs = []
    for seed in range(40):
        noisy = make_scene("torus", seed=seed, point_noise=0.5)
        plain = make_scene("torus", seed=seed)
        # The pixels, outliers and geometry of the seed are those without point noise.
        assert noisy.scene_dict["specularities"] == plain.scene_dict["specularities"]
        np.testing.assert_array_equal(noisy.clean_points, plain.points)
        assert plain.clean_points is None
        devs.append((noisy.points - plain.points) / voxel)
    devs = np.concatenate(devs).ravel()
    # 40 seeds x the torus' points x 3 axes: the sample's spread within 12% of 0.5 voxel,
    # its mean within 0.1 (a wrong unit, the domain's side or a millimetre, is far off).
    assert len(devs) >= 300
    assert abs(devs.std() / 0.5 - 1) < 0.12 and abs(devs.mean()) < 0.1
    again = make_scene("torus", seed=3, point_noise=0.5)
    np.testing.assert_array_equal(again.points, make_scene("torus", seed=3,
                                                           point_noise=0.5).points)
    assert again.truth_dict()["clean_points"] == make_scene("torus", seed=3).points.tolist()


def test_point_noise_keeps_points_in_the_domain_and_the_input_untouched():
    base = make_scene("octant")
    before = json.dumps(base.scene_dict)
    lo, hi = base.domain
    wild = jitter_points(base, sigma=10 * float(np.max(hi - lo)), seed=1)
    assert json.dumps(base.scene_dict) == before and base.clean_points is None
    assert np.all(wild.points >= lo) and np.all(wild.points <= hi)
    assert np.any(wild.points == lo) or np.any(wild.points == hi)
    # Noise on noise: the clean points stay the first ones.
    twice = jitter_points(wild, sigma=0.01, seed=2)
    np.testing.assert_array_equal(twice.clean_points, base.points)
    for bad in (-0.1, float("nan")):
        with pytest.raises(SceneError, match="sigma"):
            jitter_points(base, sigma=bad)
        with pytest.raises(SceneError, match="point_noise"):
            make_scene("octant", point_noise=bad)


def test_invalid_settings_raise():
    with pytest.raises(SceneError, match="noise"):
        make_scene("octant", noise=-1.0)
    with pytest.raises(SceneError, match="outliers"):
        make_scene("octant", outliers=1.5)
    with pytest.raises(SceneError, match="unknown name"):
        make_scene("teapot")
    with pytest.raises(SceneError, match="behind"):
        place_camera((0, 0, 1), (0, 0, 1), DirectionalLight((0, 0, -1)), distance=2)


def test_json_round_trip_and_example_file_is_current(scenes):
    s = scenes["octant"]
    assert json.loads(s.to_json()) == s.scene_dict
    path = EXAMPLES / "octant.json"
    assert path.exists(), "run examples/make_scenes.py"
    written = json.loads(path.read_text())
    assert written["format"] == "warpspec-scene" and written["version"] == 1
    assert written["light"] == s.scene_dict["light"]
    assert written["specularities"] == [
        {"camera": sp["camera"], "pixel": pytest.approx(sp["pixel"], abs=1e-9)}
        for sp in s.scene_dict["specularities"]
    ]
    np.testing.assert_allclose([c["P"] for c in written["cameras"]],
                               [c["P"] for c in s.scene_dict["cameras"]], rtol=1e-12, atol=1e-9)


def test_look_at_puts_target_at_pixel():
    intr = Intrinsics(focal=500.0, width=320, height=240)
    P = look_at((3.0, -2.0, 1.0), (0.1, 0.2, 0.3), intrinsics=intr, pixel=(40.0, 200.0))
    q, depth = project(P, np.array([[0.1, 0.2, 0.3]]))
    np.testing.assert_allclose(q[0], (40.0, 200.0), atol=1e-9)
    assert depth[0] > 0
    R = np.linalg.solve(intr.matrix(), P[:, :3])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("light", [DirectionalLight((0.0, 0.3, 1.0)), PointLight((0.5, 0.0, 4.0)),
                                   CameraLight()], ids=["directional", "point", "camera"])
@pytest.mark.parametrize("surface", [
    Sphere((0.1, 0.0, 0.0), 1.0),
    Ellipsoid((0.0, 0.0, 0.0), (1.0, 0.8, 0.6)),
    Paraboloid((0.0, 0.0, 0.5), -0.5, -0.3),
    Saddle((0.0, 0.0, 0.5), 0.3),
], ids=["sphere", "ellipsoid", "paraboloid", "saddle"])
def test_path_scene_finds_exact_highlights(surface, light):
    ang = np.linspace(-0.6, 0.6, 7)
    centres = np.column_stack([3 * np.sin(ang), -1.0 + 0 * ang, 3 * np.cos(ang)])
    s = scene_from_path(surface, centres, light=light, look_at_points=(0.0, 0.0, 0.5),
                        points=[[0.0, 0.0, 0.5]], domain=([-1.5] * 3, [1.5, 1.5, 1.2]))
    # Convex surfaces show a highlight in every view; a saddle lit by the flash shows few.
    assert len(s.truth_points) >= (7 if isinstance(surface, Sphere) else 1)
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)
    np.testing.assert_allclose(s.surface.implicit(s.truth_points), 0.0, atol=1e-12)


def test_path_scene_skips_views_without_highlight():
    sphere = Sphere((0.0, 0.0, 0.0), 1.0)
    patch = (Halfspace((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),)
    centres = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [3.0, 0.0, 0.5]])
    s = scene_from_path(sphere, centres, light=CameraLight(), look_at_points=(0.0, 0.0, 0.0),
                        points=[[0.0, 0.0, 1.0]], domain=([-1.1] * 3, [1.1] * 3), patch=patch)
    assert len(s.cameras) == 2
    np.testing.assert_allclose(s.truth_points[0], (0.0, 0.0, 1.0), atol=1e-12)
    assert find_highlight(sphere, (0.0, 0.0, -3.0), CameraLight(), patch=patch) is None


def test_cylinder_and_plane_scenes():
    cyl = Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.5, reference=(0.0, 1.0, 0.0))
    spec = cyl.at(np.array([-0.4, 0.0, 0.5]), np.array([0.1, 0.0, -0.1]))
    s = scene_from_points(cyl, spec, light=DirectionalLight((0.0, 1.0, 0.5)),
                          points=[[0.0, 0.5, 0.0]], domain=([-0.6, 0.0, -0.5], [0.6, 0.6, 0.5]),
                          pixel="centre")
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)
    np.testing.assert_allclose(s.pixels, [s.intrinsics.centre] * 3, atol=1e-9)

    plane = Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    spec = np.array([[0.1, 0.2, 0.0], [-0.3, 0.1, 0.0]])
    s = scene_from_points(plane, spec, light=PointLight((0.0, 0.0, 2.0)),
                          points=[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                          domain=([-1.2] * 3, [1.2] * 3))
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)


def test_mesh_surface_orients_and_reflects():
    ico = trimesh.creation.icosphere(subdivisions=3)
    inside_out = trimesh.Trimesh(ico.vertices, ico.faces[:, ::-1])
    surf = MeshSurface(inside_out)
    assert surf.closed and surf.mesh().volume > 0
    # Signed distance: sign right away from the surface, magnitude exact on the faces.
    q = np.random.default_rng(0).normal(size=(300, 3))
    r = np.linalg.norm(q, axis=1)
    far = np.abs(r - 0.995) > 0.02
    assert np.all(np.sign(surf.signed_distance(q[far])) == np.sign(r[far] - 0.995))
    np.testing.assert_allclose(surf.normal(ico.triangles_center), ico.face_normals, atol=1e-12)

    # Points on faces seen under a point light.
    pts = surf.sample(60, seed=1)
    pts = pts[pts[:, 2] > 0.6][:6]
    s = scene_from_points(surf, pts, light=PointLight((0.0, 0.0, 5.0)),
                          points=[[0, 0, 1], [1, 0, 0], [0, 1, 0]],
                          domain=([-1.2] * 3, [1.2] * 3))
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)

    # A flash camera on a face normal sees its highlight at the face's foot point.
    fc, fn = ico.triangles_center[::150], ico.face_normals[::150]
    s = scene_from_path(surf, fc + 3 * fn, light=CameraLight(), look_at_points=(0.0, 0.0, 0.0),
                        points=[[0, 0, 1], [1, 0, 0], [0, 1, 0]], domain=([-1.2] * 3, [1.2] * 3))
    assert len(s.cameras) == len(fc)
    np.testing.assert_allclose(s.truth_points, fc, atol=1e-12)
    check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)


def test_analytic_closest_points():
    q = np.random.default_rng(3).normal(size=(400, 3)) * 0.8
    for surf in (Torus((0.1, 0, 0), (0.1, 0.2, 1), 1.0, 0.35),
                 Revolution((0, 0, 0), (0, 0.1, 1), body=0.35, neck=0.12, shoulder=0.3,
                            width=0.1),
                 FreeformHeightField(waves=[(0.04, 5.0, 3.0, 0.2)], bumps=[(0.1, 0.1, 0, 0.15)],
                                     region=(-0.5, 0.5, -0.5, 0.5)),
                 Ellipsoid((0.1, 0.0, 0.0), (1.0, 0.7, 0.5)), Saddle((0.0, 0.0, 0.0), 0.4),
                 Paraboloid((0.0, 0.0, 0.2), -0.6, -0.4), Sphere((0, 0, 0), 0.7),
                 Cylinder((0, 0, 0), (1, 1, 0), 0.3), Plane((0, 0, 0.1), (1, 2, 3)),
                 Blob((0, 0.1, 0), 0.6, [(0.3, (1, 1, 0), 0.5), (0.2, (0, 0, -1), 0.6)])):
        cp = surf.closest_point(q)
        assert np.abs(surf.implicit(cp)).max() < 1e-12
        # The offset from the closest point is along the normal.
        off = q - cp
        sine = np.linalg.norm(np.cross(off, surf.normal(cp)), axis=1)
        assert np.all(sine < 1e-7 * np.maximum(np.linalg.norm(off, axis=1), 1e-300) + 1e-12)


def test_clip_mesh_cuts_along_the_plane():
    plane = Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), size=2.0)
    m = plane.mesh(resolution=10)
    cut = clip_mesh(m, [Halfspace((0.33, 0.0, 0.0), (1.0, 0.0, 0.0)),
                        Halfspace((0.0, -0.5, 0.0), (0.0, 1.0, 0.0))])
    assert cut.area == pytest.approx((1.0 - 0.33) * 1.5, rel=1e-12)
    assert cut.vertices[:, 0].min() == pytest.approx(0.33, abs=1e-12)
    assert np.all(cut.face_normals[:, 2] > 0.999)


def test_truth_dict_holds_what_an_evaluation_needs(scenes):
    s = scenes["ellipsoid-cap"]
    d = json.loads(json.dumps(s.truth_dict()))
    np.testing.assert_allclose(d["truth_points"], s.truth_points)
    np.testing.assert_allclose(d["truth_normals"], s.truth_normals)
    np.testing.assert_allclose(d["points"], s.points)
    assert d["outliers"] == [] and d["name"] == "ellipsoid-cap"


# --------------------------------------------------------------------------------------------
# Scenes of every shape class
# --------------------------------------------------------------------------------------------


def test_shape_scenes_are_in_the_catalogue():
    assert set(SHAPES) <= set(NAMES)


@pytest.mark.parametrize("name", SHAPES)
def test_shape_scene_reflection_law_through_the_scene_file(scenes, name, tmp_path):
    from warpspec import Scene

    s = scenes[name]
    path = tmp_path / f"{name}.json"
    s.to_json(path)
    loaded = Scene.load(path)
    assert loaded.num_specularities == len(s.truth_points)
    origins, dirs = loaded.rays()
    x = s.truth_points
    miss = np.linalg.norm(np.cross(x - origins, dirs), axis=1)
    assert np.all(miss < 1e-9 * np.linalg.norm(x - origins, axis=1))
    # The normal the reflection law gives at the true point equals the truth's normal there.
    np.testing.assert_allclose(loaded.normals(points=x), s.surface.normal(x), atol=1e-6, rtol=0)
    np.testing.assert_allclose(s.surface.implicit(x), 0.0, atol=1e-9)


@pytest.mark.parametrize("name", SHAPES)
def test_shape_scene_truth_topology_and_domain(scenes, name):
    s = scenes[name]
    mesh = s.truth_mesh()
    lo, hi = s.domain
    if name in CLOSED:
        assert s.closed and mesh.is_watertight and mesh.volume > 0
        assert s.euler == CLOSED[name] and mesh.euler_number == CLOSED[name]
        # The whole object inside the domain with a margin of 10-15% of its size.
        size = float(np.ptp(mesh.vertices, axis=0).max())
        margin = np.concatenate([mesh.vertices.min(axis=0) - lo, hi - mesh.vertices.max(axis=0)])
        assert np.all(margin > 0.10 * size) and np.all(margin < 0.15 * size)
    else:
        assert not s.closed and not mesh.is_watertight
        assert mesh.euler_number == s.euler == (0 if name.startswith("bottle") else 1)
        assert np.all(mesh.vertices >= lo - 1e-9) and np.all(mesh.vertices <= hi + 1e-9)
    d = json.loads(json.dumps(s.truth_dict()))
    assert d["closed"] == (name in CLOSED) and d["euler"] == s.euler


def test_bottle_truth_is_open_at_the_domain_ends(scenes):
    s = scenes["bottle"]
    mesh = s.truth_mesh()
    lo, hi = s.domain
    # Its two boundary loops lie on the domain's bottom and top faces.
    edges = mesh.edges_sorted
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    z = mesh.vertices[np.unique(uniq[count == 1]), 2]
    assert np.all(np.isclose(z, lo[2], atol=1e-9) | np.isclose(z, hi[2], atol=1e-9))
    assert np.any(np.isclose(z, lo[2], atol=1e-9)) and np.any(np.isclose(z, hi[2], atol=1e-9))
    # Body below, neck above: the radius shrinks by more than half.
    r = s.surface.radius(np.array([0.0, 0.8]))
    assert r[1] < 0.5 * r[0]


@pytest.mark.parametrize("name", SHAPES)
def test_shape_scene_highlights_visible_on_the_truth_mesh(scenes, name):
    from warpspec.evaluate import ray_mesh_intersect

    s = scenes[name]
    mesh = s.truth_mesh()
    c = s.camera_centres[s.camera_indices]
    hits, faces = ray_mesh_intersect(mesh, c, s.truth_points - c)
    assert np.all(faces >= 0)
    # The first hit of the ray to each true point is that point (up to the mesh's facets).
    assert np.linalg.norm(hits - s.truth_points, axis=1).max() < 5e-3
    if name in CLOSED:
        assert len(s.truth_points) >= 20
        n = s.truth_normals
        # Spread over the surface: every axis direction has highlights within 60 degrees (a
        # point lamp lights the side facing it only: the directions within 90 degrees of it)
        lamp = s.scene_dict.get("light", {})
        towards = (np.asarray(lamp["position"]) - s.truth_points.mean(axis=0)
                   if lamp.get("type") == "point" else None)
        for axis in np.concatenate([np.eye(3), -np.eye(3)]):
            if towards is None or axis @ towards > 0:
                assert (n @ axis).max() > 0.5


def test_torus_has_views_through_the_hole_and_several_highlights_per_view(scenes):
    s = scenes["torus"]
    axis = s.surface.axis
    dirs = s.camera_centres - s.surface.centre
    cosine = dirs @ axis / np.linalg.norm(dirs, axis=1)
    assert cosine.max() > 0.98 and cosine.min() < -0.98
    assert np.bincount(s.camera_indices).max() >= 2
    assert 40 <= len(s.truth_points) <= 80 and len(s.points) == 8


def test_torus_ray_intersection_is_exact():
    t = Torus((0, 0, 0), (0, 0, 1), 1.0, 0.35)
    hit = t.intersect(np.array([[3.0, 0, 0], [0, 0, 3.0], [0.5, 0.0, 3.0]]),
                      np.array([[-1.0, 0, 0], [0, 0, -1.0], [0, 0, -1.0]]))
    np.testing.assert_allclose(hit[:2], [3.0 - 1.35, np.inf])
    assert np.isinf(hit[2])  # 0.5 from the axis: through the hole (inner radius 0.65)
    hit = t.intersect(np.array([[1.0, 0, 3.0]]), np.array([[0, 0, -1.0]]))
    np.testing.assert_allclose(hit, [3.0 - 0.35], rtol=1e-14)


@pytest.mark.parametrize("name", SHAPES)
def test_seed_varies_the_shape(scenes, name):
    a, b = scenes[name], make_scene(name, seed=1)
    assert make_scene(name, seed=1).scene_dict == b.scene_dict  # same seed, same scene
    # The seed-1 surface does not pass through the seed-0 highlights.
    assert np.abs(b.surface.signed_distance(a.truth_points)).max() > 5e-3
    assert not np.allclose(a.points, b.points)


@pytest.mark.parametrize("name,fraction", [(n, 0.25) for n in SHAPES]
                         + [("sphere-around", 0.1), ("torus", 0.1)])
def test_outliers_are_false_highlights_on_the_object(name, fraction):
    s = make_scene(name, outliers=fraction, seed=2)
    m = len(s.truth_points)
    assert s.outlier_mask.sum() == round(fraction * m) > 0
    assert s.truth_dict()["outliers"] == np.flatnonzero(s.outlier_mask).tolist()
    scene = s.scene()
    origins, dirs = scene.rays()
    lo, hi = s.domain
    bad = s.outlier_mask
    t = s.surface.intersect(origins[bad], dirs[bad])
    assert np.all(np.isfinite(t))
    x = s.truth_points.copy()
    x[bad] = origins[bad] + t[:, None] * dirs[bad]
    assert np.all((x >= lo) & (x <= hi))
    law = scene.normals(points=x)
    # Where a false highlight's ray meets the object, the law's normal is wrong by >= 15 deg.
    cosine = np.einsum("ij,ij->i", law[bad], s.surface.normal(x[bad]))
    assert np.all(cosine < math.cos(math.radians(15.0)))
    # The inliers keep the law exactly.
    np.testing.assert_allclose(law[~bad], s.truth_normals[~bad], atol=1e-6, rtol=0)


def test_freeform_honours_highlights():
    for count in (30, 120):
        s = make_scene("freeform", highlights=count)
        assert len(s.truth_points) == len(s.cameras) == count
        check_reflection_law(s.scene_dict, s.truth_points, s.truth_normals)
    assert len(make_scene("freeform").truth_points) == 60
    for bad in (3, 401, 2.5, True, "60"):
        with pytest.raises(SceneError, match="highlights"):
            make_scene("freeform", highlights=bad)
    with pytest.raises(SceneError, match="highlights: scene 'torus' takes no such option"):
        make_scene("torus", highlights=30)


def test_synth_command_writes_every_shape_scene(tmp_path, capsys):
    from warpspec import Scene
    from warpspec.cli import main

    for name in ("ellipsoid-around", "bottle"):
        paths = [tmp_path / f"{name}{ext}" for ext in (".json", ".ply", ".truth.json")]
        assert main(["synth", name, "-o", str(paths[0]), "--truth", str(paths[1]),
                     "--truth-json", str(paths[2]), "--seed", "3", "--quiet"]) == 0
        scene = Scene.load(paths[0])
        truth = json.loads(paths[2].read_text())
        assert scene.num_specularities == len(truth["truth_points"])
        assert truth["closed"] == (name != "bottle") and truth["euler"] == CLOSED.get(name, 0)
        assert trimesh.load(paths[1]).is_watertight == (name != "bottle")
    out = tmp_path / "f.json"
    assert main(["synth", "freeform", "-o", str(out), "--highlights", "30", "--quiet"]) == 0
    assert Scene.load(out).num_specularities == 30
    for args, message in ((["freeform", "--highlights", "2"], "--highlights: must be"),
                          (["torus", "--highlights", "30"], "--highlights: only")):
        try:
            code = main(["synth", *args, "-o", str(tmp_path / "x.json")])
        except SystemExit as exc:
            code = exc.code
        assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize("name", SHAPES)
def test_shape_example_files_are_current(scenes, name):
    from warpspec import Scene

    s = scenes[name]
    path = EXAMPLES / f"{name}.json"
    assert path.exists(), "run examples/any_shape.py --write-scenes examples/scenes"
    loaded = Scene.load(path)
    assert loaded.num_specularities == len(s.truth_points)
    written = json.loads(path.read_text())
    np.testing.assert_allclose([sp["pixel"] for sp in written["specularities"]], s.pixels,
                               atol=1e-9)
    np.testing.assert_allclose([c["P"] for c in written["cameras"]],
                               [c["P"] for c in s.scene_dict["cameras"]], rtol=1e-12, atol=1e-9)
    truth = json.loads((EXAMPLES / f"{name}.truth.json").read_text())
    np.testing.assert_allclose(truth["truth_points"], s.truth_points, atol=1e-12)
    assert truth["closed"] == s.closed and truth["euler"] == s.euler
    mesh = trimesh.load(EXAMPLES / f"{name}.ply", process=True)
    assert mesh.is_watertight == s.closed and mesh.euler_number == s.euler


@pytest.mark.parametrize("name", NAMES)
def test_truth_json_states_the_truth_meshs_topology(scenes, name):
    s = scenes[name]
    mesh = s.truth_mesh()
    mesh.merge_vertices()
    d = s.truth_dict()
    assert d["closed"] == mesh.is_watertight and d["euler"] == mesh.euler_number


def test_blob_normal_intersection_closest_point_and_chart():
    blob = Blob((0.1, -0.05, 0.0), 0.9, [(0.25, (1, 0, 0), 0.5), (0.2, (0, 1, 1), 0.6)])
    rng = np.random.default_rng(4)
    x = rng.normal(size=(200, 3))
    # the normal is the unit gradient of the implicit function (central differences)
    eps = 1e-6
    grad = np.stack([(blob.implicit(x + eps * e) - blob.implicit(x - eps * e)) / (2 * eps)
                     for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(blob.normal(x), grad / np.linalg.norm(grad, axis=1)[:, None],
                               atol=1e-7)
    # the top of the first bump: 0.9 * (1.25 + 0.2 exp(-1 / 0.36)) from the centre
    top = 0.9 * (1.25 + 0.2 * math.exp(-1.0 / 0.36))
    t = blob.intersect(np.array([[3.0, -0.05, 0.0]]), np.array([[-1.0, 0.0, 0.0]]))
    np.testing.assert_allclose(t, [2.9 - top], rtol=1e-12)
    # rays from outside: each first hit is on the surface with the whole ray before it outside
    origins = 3.0 * _unit_rows(rng.normal(size=(50, 3)))
    dirs = _unit_rows(rng.normal(scale=0.3, size=(50, 3)) - origins)
    t = blob.intersect(origins, dirs)
    hit = np.isfinite(t)
    assert 20 < hit.sum() < 50
    assert np.abs(blob.implicit(origins[hit] + t[hit, None] * dirs[hit])).max() < 1e-12
    s = np.linspace(0.0, 1.0, 4001)[None, :-1, None] * t[hit, None, None]
    before = origins[hit, None, :] + s * dirs[hit, None, :]
    assert blob.implicit(before.reshape(-1, 3)).min() > 0.0
    # a missing ray passes outside: no sample along it is inside
    far = origins[~hit, None, :] + np.linspace(0, 6, 4001)[None, :, None] * dirs[~hit, None, :]
    assert blob.implicit(far.reshape(-1, 3)).min() > 0.0
    # a chart lies on the surface, and the closest point is along the normal
    chart = blob.chart(blob.at(np.array([[0.0, 0.6, 0.8]]))[0])
    on = np.array([chart(uv) for uv in rng.uniform(-0.3, 0.3, (20, 2))])
    assert np.abs(blob.implicit(on)).max() < 1e-12
    with pytest.raises(SceneError, match="bumps"):
        Blob((0, 0, 0), 1.0, [(0.2, (0, 0, 1), 0.0)])


def _unit_rows(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1)[:, None]


@pytest.mark.parametrize("name, seed", [("bottle", 2), ("bottle-lamps", 0)])
def test_a_ray_along_the_bottles_axis_outside_it_misses(name, seed):
    """A ray parallel to the axis of a surface of revolution, outside its body, meets nothing.
    Its span inside the bounding cylinder is empty or unbounded; the march overflowed
    converting an infinite span to a sample count."""
    surf = make_scene(name, seed=seed).surface
    base = surf.base + 2 * surf.body * surf.e1 - 3 * surf.axis
    assert np.all(np.isinf(surf.intersect(base[None], surf.axis[None])))


@pytest.mark.parametrize("name, seed", [("bottle", 1), ("bottle", 2), ("bottle-lamps", 0)])
def test_a_ray_along_the_bottles_axis_meets_its_shoulder(name, seed):
    """A ray parallel to the axis (exactly, or within float rounding: the scenes' axes give
    both), midway between the neck's and the body's radius, crosses the shoulder at its
    middle height, where the radius is their mean."""
    surf = make_scene(name, seed=seed).surface
    o = surf.base + 0.5 * (surf.body + surf.neck) * surf.e1 - 3 * surf.axis
    t = surf.intersect(o[None], surf.axis[None])[0]
    assert abs(t - 3 - surf.shoulder) < 1e-9
