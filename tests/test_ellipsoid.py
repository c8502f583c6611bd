"""The ellipsoid refitted in pixels with the points weighed as noisy."""

import numpy as np
import pytest

import warpspec as ws
from warpspec import quadric as Q
from warpspec.ellipsoid import Ellipsoid, pixel_misses, refit_ellipsoid
from warpspec.synthetic import make_scene


def _rotation(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


def _ellipsoid(centre, radii, rotation) -> Ellipsoid:
    R = np.asarray(rotation, float)
    return Ellipsoid(np.asarray(centre, float), R @ np.diag(1.0 / np.square(radii)) @ R.T)


def _truth(synthetic) -> Ellipsoid:
    s = synthetic.surface
    return _ellipsoid(s.centre, s.radii, np.eye(3))


def test_an_ellipsoid_is_the_quadric_it_gives_and_a_hyperboloid_is_none():
    """To a quadric in another frame and back: the same centre and matrix to 1e-12; the
    quadric vanishes on the ellipsoid's points with given normals, its gradient along them.
    A hyperboloid, a cylinder, an empty quadric and the outside of a sphere (an object about
    a hollow) give no ellipsoid."""
    shape = _ellipsoid([0.1, -0.2, 0.05], [1.0, 0.6, 0.3], _rotation(0))
    quad = shape.quadric(centre=np.array([0.3, 0.0, -0.1]), scale=1.7)
    back = Ellipsoid.from_quadric(quad)
    np.testing.assert_allclose(back.centre, shape.centre, atol=1e-12)
    np.testing.assert_allclose(back.matrix, shape.matrix, atol=1e-12)
    np.testing.assert_allclose(back.radii, [0.3, 0.6, 1.0], atol=1e-12)
    normals = np.random.default_rng(1).standard_normal((50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    at = shape.normal_points(normals)
    assert np.abs(quad.value(at)).max() < 1e-12
    g = quad.gradient(at)
    np.testing.assert_allclose(g / np.linalg.norm(g, axis=1, keepdims=True), normals,
                               atol=1e-12)
    frame = {"frame_centre": np.zeros(3), "scale": 1.0}
    for coeffs in ([1, 1, -1, 0, 0, 0, 0, 0, 0, -1],   # a hyperboloid of one sheet
                   [1, 1, 0, 0, 0, 0, 0, 0, 0, -1],    # a cylinder
                   [1, 1, 1, 0, 0, 0, 0, 0, 0, 1],     # no real point
                   [-1, -1, -1, 0, 0, 0, 0, 0, 0, 1]):  # the outside of a sphere
        assert Ellipsoid.from_quadric(Q.Quadric(np.array(coeffs, float), **{
            "centre": frame["frame_centre"], "scale": frame["scale"]})) is None


def test_first_hits_are_the_rays_first_crossings_and_misses_come_nearest():
    """A ray through the ellipsoid meets it first where sampling along it finds q change sign
    (to 1e-9); one passing it by 1e-4 gets its nearest approach, 1e-4 off, beside the
    tangent point; one from inside meets it ahead; the signed distance of points 1e-3 off is
    1e-3 to first order."""
    shape = _ellipsoid([0.0, 0.0, 0.0], [1.0, 0.6, 0.3], _rotation(2))
    rng = np.random.default_rng(3)
    origins = 4.0 * rng.standard_normal((40, 3))
    aims = 0.2 * rng.standard_normal((40, 3))
    dirs = aims - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = shape.first_hits(origins, dirs)
    t = np.linspace(0.0, 12.0, 120001)
    crossing = 0
    for o, d, hit in zip(origins, dirs, hits, strict=True):
        inside = shape.distance(o + t[:, None] * d) < 0.0
        if inside.any():
            crossing += 1
            assert abs(shape.distance(hit[None])[0]) < 1e-9
            assert abs(float((hit - o) @ d) - t[np.argmax(inside)]) < 1e-4
    assert crossing >= 30
    # a ray along the long axis' tangent at the short axis' tip, lifted 1e-4 off it
    R = np.linalg.eigh(shape.matrix)[1]  # columns: the long, middle and short axes
    tip = shape.centre + (0.3 + 1e-4) * R[:, 2]
    start = tip - 5.0 * R[:, 0]
    passing = shape.first_hits(start[None], R[:, 0][None])[0]
    assert abs(shape.distance(passing[None])[0] - 1e-4) < 1e-7
    assert np.linalg.norm(passing - tip) < 1e-6
    # a ray from the centre meets it ahead, at the long axis' tip
    ahead = shape.first_hits(shape.centre[None], R[:, 0][None])[0]
    np.testing.assert_allclose(ahead, shape.centre + R[:, 0], atol=1e-12)
    normals = shape.normal_points(np.eye(3)) - shape.centre
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    at = shape.normal_points(np.eye(3))
    grad = at @ shape.matrix
    grad /= np.linalg.norm(grad, axis=1, keepdims=True)
    np.testing.assert_allclose(shape.distance(at + 1e-3 * grad), 1e-3, rtol=2e-3)


def _rays(scene, truth: Ellipsoid):
    """The rays, the normals they ask (a function of their hits) and their pixels."""
    origins, dirs = scene.rays()

    def asked(at: np.ndarray) -> np.ndarray:
        return scene.normals(at)

    return origins, dirs, asked, scene.pixel_angles()


@pytest.mark.parametrize("name", ["ellipsoid-around", "pebble", "ellipsoid-cap"])
def test_rays_pass_the_points_with_their_normals_by_their_pixel_misses(name):
    """Exact highlights pass the true ellipsoid's points with the normals they ask within
    1e-6 px; highlights moved by (1.5, -1) px, 1.8 px, by a median of 2.0-2.1 px under lamps,
    2.8 under the point lamp (the cap), where the normal a ray asks turns as it moves: the
    ray's move alone is measured."""
    from .helpers import highlights_moved

    synthetic = make_scene(name, seed=0)
    truth = _truth(synthetic)
    scene, moved = highlights_moved(synthetic.scene(), 3)
    misses = pixel_misses(truth, *_rays(scene, truth))
    assert misses[~moved].max() < 1e-6
    assert misses[moved].min() > 0.5
    assert 0.8 * 1.8 < np.median(misses[moved]) < 1.8 * (1.3 if name != "ellipsoid-cap" else 1.8)


@pytest.mark.parametrize(("name", "seed"), [("pebble", 0), ("pebble", 4),
                                            ("ellipsoid-around", 1)])
def test_under_lamps_the_rays_fix_the_ellipsoid_not_the_noisy_points(name, seed):
    """Under a lamp per camera the rays alone fix an ellipsoid: from a start a voxel off along
    each axis, its matrix 20% and 10% off on two axes, exact highlights and no points bring it
    back to 1e-6 voxel. With points a voxel off per axis and half a pixel on the highlights
    the refit's radii and centre are within 0.06 voxel (0.005-0.05), where the quadric fitted
    algebraically with the points as noisy is 0.4-1.2 voxel off in one or the other."""
    from .helpers import points_moved

    synthetic = make_scene(name, seed=seed)
    truth = _truth(synthetic)
    lo, hi = synthetic.scene().bounds()
    voxel = float(np.max(hi - lo)) / 64
    start = Ellipsoid(truth.centre + voxel,
                      truth.matrix * np.array([[1.2, 1, 1], [1, 1, 1], [1, 1, 0.9]]))

    def error(shape: Ellipsoid) -> float:
        return max(np.abs(shape.radii - truth.radii).max(),
                   np.linalg.norm(shape.centre - truth.centre)) / voxel

    exact = refit_ellipsoid(start, *_rays(synthetic.scene(), truth), np.zeros((0, 3)),
                            voxel=voxel)
    assert error(exact) < 1e-6
    scene = points_moved(make_scene(name, seed=seed, noise=0.5).scene(), 1.0)
    fit = refit_ellipsoid(start, *_rays(scene, truth), scene.points, voxel=voxel)
    assert error(fit) < 0.06
    centre = 0.5 * (lo + hi)
    algebraic, _, _ = Q.fit_quadric(
        scene, start.quadric(centre=centre, scale=float(np.max(hi - lo))), lo=lo, hi=hi,
        voxel=voxel, point_weight=Q.NOISY_POINT_WEIGHT)
    assert error(Ellipsoid.from_quadric(algebraic)) > 0.3


@pytest.mark.parametrize("seed", [0, 4, 5])
def test_points_scattered_by_a_voxel_let_a_flat_ellipsoid_be_the_start(seed):
    """The pebble (axes 1, 0.9, 0.3-0.4) under lamps, its six points moved by a voxel per axis
    and half a pixel on the highlights. No quadric was the start: the one that held the points
    met 11-21% of the normals within 3 degrees, the one that let them go 75-82%, and the grid
    fit came out 0.77-1.06 h off. The ellipsoid refitted in pixels meets every normal and is
    the start: 0.024-0.037 h end to end."""
    from .helpers import points_moved

    synthetic = make_scene("pebble", seed=seed, noise=0.5)
    solver = ws.Reconstructor(points_moved(synthetic.scene(), 1.0), resolution=64,
                              device="cpu")
    assert solver.fit_report.shape == "quadric"
    solver.run(20)
    result = solver.result()
    assert result.mesh.is_watertight and result.mesh.euler_number == 2
    distance = np.abs(synthetic.surface.signed_distance(result.vertices))
    assert distance.mean() < 0.1 * result.grid.spacing


def test_a_points_distance_in_pixels_is_over_a_pixels_width_at_its_median_depth():
    """Three cameras at 2, 3 and 5 from a point: its median depth is 3, and a distance of
    3 pixel widths there is 1 px; a ray passing a target 2 pixel widths off at depth 4 misses
    it by 2 px."""
    from warpspec.pixel_fit import point_pixels, ray_misses

    pixel = 1.0 / 800.0
    point = np.array([[0.1, 0.2, 0.3]])
    centres = point + np.array([[2.0, 0, 0], [0, -3.0, 0], [0, 0, 5.0]])
    assert abs(point_pixels(np.array([3.0 * pixel]), point, centres, pixel)[0] - 1.0) < 1e-12
    origin, direction = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    target = np.array([[2.0 * 4.0 * pixel, 0.0, 4.0]])
    assert abs(ray_misses(target, origin, direction, np.array([pixel]))[0] - 2.0) < 1e-12
