"""The implicit start: the grid fit's kernels, the quadric, the first guess and the ladder."""

import numpy as np
import pytest
import trimesh
import warp as wp

import warpspec as ws
from warpspec import quadric as Q
from warpspec.geometry import crop_to_data_hull, crop_to_unwrapped_hull
from warpspec.grid import Grid
from warpspec.implicit import (
    NOISE_SPREAD,
    PIXEL_MET,
    PIXEL_NOISE,
    PIXEL_WIDEST,
    ImplicitStart,
    box_frame,
    first_guess,
    level_ladder,
    ray_convergence,
)
from warpspec.kernels import implicit as K
from warpspec.mesh import (
    faces_behind,
    is_open,
    supported_components,
    triangulate,
    vertex_components,
)
from warpspec.solver import initial_plane
from warpspec.synthetic import make_scene
from warpspec.synthetic.surfaces import Cylinder


def _field(values: np.ndarray, device: str) -> wp.array:
    return wp.array(values.astype(np.float32), dtype=float, device=device)


def _hessian_energy_operator(f: np.ndarray, device: str, lam: float = 1.0,
                             eps: float = 0.0) -> np.ndarray:
    shape = f.shape
    x = _field(f, device)
    second = wp.zeros(shape, dtype=wp.vec3, device=device)
    mixed = wp.zeros(shape, dtype=wp.vec3, device=device)
    out = wp.zeros(shape, dtype=float, device=device)
    wp.launch(K.hessian_terms, dim=shape, inputs=[0, x], outputs=[second, mixed], device=device)
    wp.launch(K.hessian_adjoint, dim=shape, inputs=[0, second, mixed, x, lam, eps], outputs=[out],
              device=device)
    return out.numpy().astype(np.float64)


def _shifted(f: np.ndarray, a: int, b: int, da: int, db: int) -> np.ndarray:
    idx = [slice(None)] * 3  # every node along the third axis
    idx[a] = slice(1 + da, f.shape[a] - 1 + da)
    idx[b] = slice(1 + db, f.shape[b] - 1 + db)
    return f[tuple(idx)]


def _cross(f: np.ndarray, a: int, b: int) -> np.ndarray:
    """The quarter cross difference along axes ``a`` and ``b`` on its interior nodes."""
    return 0.25 * (_shifted(f, a, b, 1, 1) - _shifted(f, a, b, 1, -1)
                   - _shifted(f, a, b, -1, 1) + _shifted(f, a, b, -1, -1))


def _energy(f: np.ndarray) -> float:
    """Sum over interior stencils of the squared Hessian (mixed terms twice), in NumPy."""
    e = sum(float(np.sum(np.diff(f, n=2, axis=a) ** 2)) for a in range(3))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        e += 2.0 * float(np.sum(_cross(f, a, b) ** 2))
    return e


def _assert_half_gradient(op: np.ndarray, energy, f: np.ndarray, nodes, *, rel: float,
                          abs: float) -> None:
    """``op`` is half the gradient of ``energy`` at ``f``: central differences at ``nodes``
    (exact for a quadratic energy)."""
    for idx in nodes:
        up, down = f.copy(), f.copy()
        up[idx] += 1e-3
        down[idx] -= 1e-3
        numeric = (energy(up) - energy(down)) / 2e-3
        assert op[idx] * 2.0 == pytest.approx(numeric, rel=rel, abs=abs)


def test_hessian_operator_is_the_gradient_of_the_hessian_energy(device):
    """``D^T W D f`` is half the gradient of the energy: checked against finite differences."""
    rng = np.random.default_rng(0)
    f = rng.normal(size=(6, 7, 5))
    _assert_half_gradient(_hessian_energy_operator(f, device), _energy, f,
                          [(0, 0, 0), (2, 3, 1), (5, 6, 4), (3, 0, 2), (1, 4, 4)],
                          rel=1e-5, abs=1e-4)


def test_hessian_operator_vanishes_on_linear_fields_and_not_on_quadratics(device):
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for n in (8, 9, 7)), indexing="ij")
    linear = 0.3 * i - 1.2 * j + 0.7 * k + 2.0
    assert np.max(np.abs(_hessian_energy_operator(linear, device))) < 1e-4
    # f = x^2: the interior second difference is 2, and the operator in the deep interior is
    # the fourth difference of x^2 (zero) in x: the stencil sees only constant curvature.
    quad = i**2
    op = _hessian_energy_operator(quad, device)
    assert np.max(np.abs(op[3:5, 2:7, 2:5])) < 1e-3
    # at the boundary the constant curvature is not balanced: the energy pulls there
    assert np.max(np.abs(op[0])) > 1.0


def test_hessian_diagonal_matches_the_operator(device):
    shape = (5, 6, 4)
    diag = wp.zeros(shape, dtype=float, device=device)
    wp.launch(K.hessian_diagonal, dim=shape, inputs=[wp.vec3i(*shape), 1.0, 0.0],
              outputs=[diag], device=device)
    d = diag.numpy()
    for idx in [(0, 0, 0), (2, 3, 1), (4, 5, 3), (1, 1, 2)]:
        e = np.zeros(shape)
        e[idx] = 1.0
        assert d[idx] == pytest.approx(_hessian_energy_operator(e, device)[idx], rel=1e-6)


def _third_energy_operator(f: np.ndarray, device: str, second: float = 0.0,
                           third: float = 1.0) -> np.ndarray:
    shape = f.shape
    x = _field(f, device)
    h = [wp.zeros(shape, dtype=wp.vec3, device=device) for _ in range(4)]
    out = wp.zeros(shape, dtype=float, device=device)
    wp.launch(K.hessian_terms, dim=shape, inputs=[0, x], outputs=[h[0], h[1]], device=device)
    wp.launch(K.third_terms, dim=shape, inputs=[0, h[0], h[1], second, third],
              outputs=[h[2], h[3]], device=device)
    wp.launch(K.hessian_adjoint, dim=shape, inputs=[0, h[2], h[3], x, 1.0, 0.0], outputs=[out],
              device=device)
    return out.numpy().astype(np.float64)


def _third_energy(f: np.ndarray) -> float:
    """``sum |D^3 f|^2`` in NumPy: first differences of each interior Hessian component."""
    e = 0.0
    for a in range(3):
        d2 = np.diff(f, n=2, axis=a)  # the component (a, a) on its interior nodes
        e += sum(float(np.sum(np.diff(d2, axis=b) ** 2)) for b in range(3))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        cross = _cross(f, a, b)
        e += 2.0 * sum(float(np.sum(np.diff(cross, axis=c) ** 2)) for c in range(3))
    return e


def test_third_order_operator_is_the_gradient_of_its_energy(device):
    rng = np.random.default_rng(1)
    f = rng.normal(size=(7, 6, 8))
    op = _third_energy_operator(f, device)
    _assert_half_gradient(op, _third_energy, f,
                          [(0, 0, 0), (3, 2, 4), (6, 5, 7), (1, 0, 3), (4, 5, 1)],
                          rel=1e-4, abs=1e-3)
    # with both weights: the Hessian operator plus the third-order one
    both = _third_energy_operator(f, device, second=0.5, third=2.0)
    expected = 0.5 * _hessian_energy_operator(f, device) + 2.0 * op
    assert np.max(np.abs(both - expected)) < 1e-3


def test_third_order_energy_of_cubics_and_its_null_space(device):
    """Quadratics cost nothing; ``x^3`` and ``x^2 y`` cost what ``|D^3 f|^2`` says."""
    n = 9
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for _ in range(3)), indexing="ij")
    quad = 0.3 * i**2 - 0.5 * i * j + 0.2 * k**2 + j - 2.0
    assert np.max(np.abs(_third_energy_operator(quad, device))) < 1e-3
    # x^3: second difference 6x, its first difference 6 on the (n - 3) pairs of each line
    cube = i**3
    energy = float(np.sum(cube * _third_energy_operator(cube, device)))
    assert energy == pytest.approx(36.0 * (n - 3) * n * n, rel=1e-4)
    # x^2 y: f_xx = 2y (steps of 2 along y), f_xy = 2x (counted twice, steps of 2 along x)
    mixed = i**2 * j
    energy = float(np.sum(mixed * _third_energy_operator(mixed, device)))
    assert energy == pytest.approx(4.0 * n * (n - 2) * (n - 1) + 8.0 * n * (n - 3) * (n - 2),
                                   rel=1e-4)
    # the Hessian energy alone does not vanish on the quadratic: the third order is what adds
    assert np.max(np.abs(_hessian_energy_operator(quad, device))) > 0.1


def test_ray_anchor_finds_the_sphere_and_the_nearest_approach(device):
    grid = Grid(origin=np.full(3, -1.0), spacing=0.05, shape=(41, 41, 41))
    f = wp.zeros(grid.shape, dtype=float, device=device)
    wp.launch(K.sphere_field, dim=grid.shape,
              inputs=[wp.vec3(-1.0, -1.0, -1.0), 0.05, wp.vec3(0.1, 0.0, 0.0), 0.5],
              outputs=[f], device=device)
    origins = np.array([[0.1, 0.0, 3.0], [0.1, 0.8, 3.0]])
    dirs = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    anchor = wp.zeros(2, dtype=wp.vec3, device=device)
    kind = wp.zeros(2, dtype=int, device=device)
    normals = wp.zeros(2, dtype=wp.vec3, device=device)
    wp.launch(K.ray_anchor, dim=2,
              inputs=[f, wp.vec3(-1.0, -1.0, -1.0), 0.05,
                      wp.array(origins.astype(np.float32), dtype=wp.vec3, device=device),
                      wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=device),
                      wp.array(np.full(2, 2, dtype=np.int32), dtype=int, device=device),
                      wp.zeros(2, dtype=wp.vec3, device=device)],
              outputs=[anchor, kind, normals], device=device)
    a, k, n = anchor.numpy(), kind.numpy(), normals.numpy()
    assert k[0] == K.ANCHOR_CROSSING
    assert np.allclose(a[0], [0.1, 0.0, 0.5], atol=2e-3)  # trilinear of an exact distance
    assert np.allclose(n[0], [0.0, 0.0, 1.0], atol=1e-6)  # flash: N = -r
    assert k[1] == K.ANCHOR_NEAREST  # passes 0.3 beside the sphere
    assert abs(a[1][2] - 0.0) < 0.05  # nearest approach at the sphere's equator


def test_quadric_intersection_is_exact():
    sphere = Q.sphere(np.array([0.2, 0.0, 0.0]), 0.5, frame_centre=np.zeros(3), scale=2.0)
    origins = np.array([[0.2, 0.0, 5.0], [0.2, 0.4, 5.0], [3.0, 3.0, 5.0]])
    dirs = np.array([[0.0, 0.0, -1.0]] * 3)
    anchors, crossing, inside = sphere.intersect(origins, dirs, np.full(3, -1.0),
                                                 np.full(3, 1.0))
    assert crossing.tolist() == [True, True, False]
    assert inside.tolist() == [True, True, False]
    assert np.allclose(anchors[0], [0.2, 0.0, 0.5], atol=1e-12)
    assert np.allclose(anchors[1], [0.2, 0.4, 0.3], atol=1e-12)


@pytest.mark.parametrize("name", ["octant", "car-window", "sphere-around", "ellipsoid-around"])
def test_the_quadric_fit_recovers_quadric_scenes_exactly(name):
    synthetic = make_scene(name)
    scene = synthetic.scene()
    lo, hi = scene.bounds()
    grid = Grid.from_bounds(lo, hi, resolution=64)
    guess = first_guess(scene, grid, initial_plane(scene, grid))
    frame, scale = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo))
    start = (Q.sphere(guess.centre, guess.radius, frame_centre=frame, scale=scale)
             if guess.kind == "sphere" else
             Q.plane(guess.centre, guess.normal, frame_centre=frame, scale=scale))
    quad, weights, angle = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing)
    truth = synthetic.truth_points
    dist = quad.distance(truth)
    assert dist.max() < 1e-3 * grid.spacing
    assert np.all(weights > 0) and angle.max() < 0.01


def test_the_quadric_fit_rejects_false_highlights():
    synthetic = make_scene("sphere-around", outliers=0.25)
    scene = synthetic.scene()
    lo, hi = scene.bounds()
    grid = Grid.from_bounds(lo, hi, resolution=64)
    guess = first_guess(scene, grid, initial_plane(scene, grid))
    frame, scale = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo))
    start = Q.sphere(guess.centre, guess.radius, frame_centre=frame, scale=scale)
    quad, weights, _ = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing)
    assert np.array_equal(weights == 0, synthetic.outlier_mask)
    inliers = synthetic.truth_points[~synthetic.outlier_mask]
    dist = quad.distance(inliers)
    assert dist.max() < 1e-3 * grid.spacing


def _guess_start(scene, radius: float | None = None):
    """The grid at 64, its box, the first guess, the quadrics' scale and a sphere about the
    guess (its own radius, or ``radius``)."""
    grid = Grid.from_bounds(*scene.bounds(), resolution=64)
    lo, hi = grid.origin, grid.upper
    guess = first_guess(scene, grid, initial_plane(scene, grid))
    frame, scale = box_frame(lo, hi)
    start = Q.sphere(guess.centre, guess.radius if radius is None else radius,
                     frame_centre=frame, scale=scale)
    return grid, lo, hi, guess, scale, start


def test_the_quadric_fit_to_some_rays_measures_every_ray():
    """Fitted to the true rays alone (``use``), the quadric is the sphere, and the false
    rays' residuals are measured against it: each off by the 15 degrees or more they were
    drawn with."""
    synthetic = make_scene("sphere-around", outliers=0.25)
    scene = synthetic.scene()
    grid, lo, hi, _, scale, start = _guess_start(scene)
    true = ~synthetic.outlier_mask
    quad, weights, angle = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing,
                                         robust_from=Q.ROUNDS, use=true)
    assert np.array_equal(weights > 0, true)
    assert angle[true].max() < 0.01 and angle[~true].min() > 14.0
    inliers = synthetic.truth_points[true]
    dist = quad.distance(inliers)
    assert dist.max() < 1e-3 * grid.spacing


@pytest.mark.parametrize(("seed", "consensus"), [(4, False), (6, False), (9, True)])
def test_a_flat_object_is_found_despite_its_start_and_false_highlights(seed, consensus):
    """The pebble (a flat ellipsoid under lamps) with a quarter false. From the sphere
    through its points the quadric fit settles on a wrong quadric (no normal met); on seeds 4
    and 6 the fit from the sphere as wide as the domain meets every true one. On seed 9 the
    false highlights drag the fit from either sphere off, and fits to subsets of six rays
    find the quadric. The start is that quadric, and rejects exactly the false highlights."""
    synthetic = make_scene("pebble", seed=seed, outliers=0.25)
    scene = synthetic.scene()
    grid, lo, hi, guess, scale, _ = _guess_start(scene)
    for radius, met in ((guess.radius, False), (scale, not consensus)):
        start = _guess_start(scene, radius)[-1]
        _, _, angle = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing)
        assert np.array_equal(angle <= 3.0, ~synthetic.outlier_mask) if met else (
            np.mean(angle <= 3.0) < 0.1)

    start = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    report = start.run(wp.zeros(grid.shape, dtype=float, device="cpu"))
    assert report.shape == "quadric"
    assert np.array_equal(report.weights == 0, synthetic.outlier_mask)
    truth = synthetic.truth_points[~synthetic.outlier_mask]
    quad = start.quadric
    dist = quad.distance(truth)
    assert dist.max() < 0.01 * grid.spacing


def _pebble_under_a_lamp(seed: int, outliers: float = 0.0):
    """A flat ellipsoid seen all around by 28 cameras under one point lamp above it."""
    from warpspec.synthetic import catalogue as C
    from warpspec.synthetic.scenes import scene_from_path
    from warpspec.synthetic.surfaces import Ellipsoid

    rng = np.random.default_rng(seed + 1000)
    surf = Ellipsoid([0.0, 0.0, 0.0], [1.0, 0.9, 0.35])
    mesh = surf.mesh(subdivisions=5)
    lamp = C.PointLight(3.0 * np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0]))
    return scene_from_path(
        surf, 3.2 * C._around(28, rng), light=lamp, look_at_points=np.zeros(3),
        points=C._pick_points(mesh.vertices, surf, 6, rng), domain=C._margin_box(mesh.vertices),
        candidates=mesh.vertices, closed=True, euler=2, outliers=outliers, seed=seed,
        false_highlights="surface")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_under_a_point_light_the_quadric_fit_settles(seed, monkeypatch):
    """Under a point lamp the normal a ray asks moves with its hit. Undamped, the fit of a
    flat ellipsoid from the sphere through its points goes round between quadrics either side
    of the truth and misses some normals by 3-6 degrees; damped, it meets every one within
    3 degrees but at most one, and the start is the quadric."""
    synthetic = _pebble_under_a_lamp(seed)
    scene = synthetic.scene()
    grid, lo, hi, _, _, start = _guess_start(scene)
    _, _, damped = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing)
    assert np.sum(damped > 3.0) <= 1
    fit = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    assert fit.run(wp.zeros(grid.shape, dtype=float, device="cpu")).shape == "quadric"
    monkeypatch.setattr(Q, "POINT_DAMPING", 0.0)
    _, _, undamped = Q.fit_quadric(scene, start, lo=lo, hi=hi, voxel=grid.spacing)
    assert np.sum(undamped > 3.0) >= 2


def test_grazing_true_highlights_missed_by_degrees_but_not_pixels_are_kept():
    """The flat ellipsoid under a lamp, seed 2, a tenth false: from every start the fit
    misses two grazing true normals by 6.6 and 9.0 degrees (from the truth it meets them
    all), which kept it from being the start: a subset's fit was. Their highlights need move
    at most 1.4 px for the fit to meet them, so it is the start, and it keeps them: it rejects
    exactly the false highlights (its robust weights had let the two go too)."""
    synthetic = _pebble_under_a_lamp(2, outliers=0.1)
    scene = synthetic.scene()
    grid = Grid.from_bounds(*scene.bounds(), resolution=64)
    fit = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    report = fit.run(wp.zeros(grid.shape, dtype=float, device="cpu"))
    assert report.shape == "quadric"
    assert np.array_equal(report.weights == 0, synthetic.outlier_mask)
    true = ~synthetic.outlier_mask
    assert np.sum(report.residual_deg[true] > 3.0) == 2
    rays = report.residual_deg < 180.0
    assert fit._pixel_miss(fit.quadric, rays)[true & rays].max() < 1.5


def test_height_map_is_a_single_sheet_over_the_plane():
    frame = np.eye(3)  # u = x, v = y, normal z
    T, c0 = Q.height_map(frame)
    theta = np.array([0.5, -0.2, 0.3, 0.1, -0.4, 0.05])
    quad = Q.Quadric(c0 + T @ theta, np.zeros(3), 1.0)
    rng = np.random.default_rng(1)
    uv = rng.uniform(-1, 1, size=(20, 2))
    a, b, c, d, e, f0 = theta
    z = a * uv[:, 0] ** 2 + b * uv[:, 0] * uv[:, 1] + c * uv[:, 1] ** 2 + d * uv[:, 0] \
        + e * uv[:, 1] + f0
    on = np.column_stack([uv, z])
    assert np.allclose(quad.value(on), 0.0, atol=1e-12)
    assert np.all(quad.value(on + [0, 0, 0.1]) > 0)  # above the sheet: outside, one sheet


def test_first_guess_follows_where_the_cameras_stand():
    for name, kind in (("sphere-around", "sphere"), ("torus", "sphere"), ("wrap", "sphere"),
                       ("car-window", "plane"), ("freeform", "plane")):
        scene = make_scene(name).scene()
        lo, hi = scene.bounds()
        grid = Grid.from_bounds(lo, hi, resolution=32)
        assert first_guess(scene, grid, initial_plane(scene, grid)).kind == kind, name


def test_ray_convergence_of_rays_through_one_point():
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(12, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    centre = np.array([0.3, -0.2, 1.5])
    origins = centre - 4.0 * dirs
    assert np.allclose(ray_convergence(origins, dirs), centre, atol=1e-9)
    assert ray_convergence(origins[:1], dirs[:1]) is None


def test_level_ladder():
    assert level_ladder(64) == [16, 32, 64]
    assert level_ladder(100) == [16, 32, 64, 100]
    assert level_ladder(16) == [16]
    assert level_ladder(12) == [12]


def test_closed_object_comes_out_closed_and_accurate():
    """A sphere seen all around, default options, a coarse grid: watertight, Euler 2."""
    synthetic = make_scene("sphere-around")
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    mesh = result.mesh.copy()
    mesh.merge_vertices()
    assert mesh.is_watertight and mesh.euler_number == 2
    centre, radius = synthetic.surface.centre, synthetic.surface.radius
    err = np.abs(np.linalg.norm(result.vertices - centre, axis=1) - radius)
    assert err.mean() < 0.1 * result.grid.spacing
    assert result.rejected == []


def test_false_highlights_are_rejected_and_reported():
    synthetic = make_scene("ellipsoid-around", outliers=0.25)
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    assert sorted(r["index"] for r in result.rejected) == \
        np.flatnonzero(synthetic.outlier_mask).tolist()
    for r in result.rejected:
        assert set(r) == {"index", "camera", "pixel", "residual_deg"}
        assert r["residual_deg"] > 5.0


@pytest.mark.parametrize("seed", [0, 1, 8])
def test_false_highlights_on_a_shape_that_is_no_quadric_are_rejected(seed):
    """A bumpy dome under a point lamp (no quadric: the grid fit decides). Its robust
    passes (stiff to supple) reject exactly the false highlights, and none of a clean scene
    (a true ray a stiff pass misses comes back). Seed 8 keeps one false highlight when a pass
    rejects beyond four robust standard deviations instead of three. Tried back together,
    the false ones are met by a fit that bends to them (2-5 of 8 stay on each seed when the
    trial is taken whatever the kept rays' median miss does)."""
    for outliers in (0.0, 0.25):
        synthetic = make_scene("point-light", outliers=outliers, seed=seed)
        result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
        assert sorted(r["index"] for r in result.rejected) == \
            np.flatnonzero(synthetic.outlier_mask).tolist()


@pytest.mark.parametrize("seed", [6, 11])
def test_true_highlights_a_stiff_pass_misses_all_come_back(seed):
    """On the clean free-form patch the stiff robust passes miss true highlights on its
    bump and waves (9 and 8 of 60 on these seeds at 32 cells); they come back once the fit
    made without them meets them, the ladder being refitted from that fit. On seed 1, 2 of 5
    stay out: the final fit misses them by 15.8 and 16.9 degrees, just past the return's
    15."""
    synthetic = make_scene("freeform", seed=seed)
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    assert result.rejected == []


@pytest.mark.parametrize("seed", [4, 10])
def test_false_highlights_a_supple_fit_follows_are_rejected_by_cross_validation(seed):
    """On the free-form patch with 6 of 60 highlights false, the fit bends to most false
    normals, and the robust passes reject only 2 of them on these seeds (at 32 cells). Left
    out one at a time, the false ones are missed by the fits made without them far more than
    the true ones: at least 4 are rejected, and no true one. (Two of seed 4's are hits at
    corners of the hits' hull, where a fit without them extrapolates and only a miss past
    CV_HULL_DEG counts. Ten folds and a limit of 3 robust standard deviations rejected 5 on
    each seed here, but 1-4 of 15 with a quarter false at 64 cells, seeds 3, 5, 7, 12, where
    the leave-one-out passes reject 6-11.)"""
    synthetic = make_scene("freeform", seed=seed, outliers=0.1)
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    rejected = {r["index"] for r in result.rejected}
    false = set(np.flatnonzero(synthetic.outlier_mask).tolist())
    assert rejected <= false
    assert len(rejected) >= 4


def test_a_true_normal_at_a_corner_of_the_hits_hull_is_kept_by_cross_validation():
    """On the clean free-form patch with 30 highlights (seed 0), ray 1 meets it at a corner
    of the hits' hull, where a fit made without it extrapolates: a corner's limit is wider
    than the inner rays' (CV_HULL_DEG against CV_DEG). Rejected, the patch was 0.60 h off at
    64 cells instead of 0.43."""
    synthetic = make_scene("freeform", seed=0, highlights=30)
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    assert 1 not in {r["index"] for r in result.rejected}


def _seen_from_one_side(xy: np.ndarray) -> ImplicitStart:
    """A start seen from one side (the plane z = 0) whose rays cross it at ``xy``, no fit."""
    start = ImplicitStart.__new__(ImplicitStart)
    start.m, start._one_side, start.plane = len(xy), True, (np.zeros(3), np.array([0, 0, 1.0]))
    start.kind = wp.array(np.full(len(xy), K.ANCHOR_CROSSING, dtype=np.int32), dtype=int)
    start.anchor = wp.array(np.c_[xy, np.zeros(len(xy))].astype(np.float32), dtype=wp.vec3)
    return start


def _corners(xy: np.ndarray) -> np.ndarray:
    """``ImplicitStart._on_hull`` of every ray, their hits at ``xy`` in the plane z = 0."""
    return _seen_from_one_side(xy)._on_hull(np.arange(len(xy)))


def test_a_hull_corner_counts_unless_a_hit_is_nearer_than_the_hits_median_spacing():
    """Hits spread over a square with its four corners: each corner is extrapolated to by a
    fit without it. A hit put 0.01 from one corner (the spacing is about 0.1) takes that corner
    and itself out: a fit without either is carried there from the other. Hits on a line are
    all corners."""
    rng = np.random.default_rng(3)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    xy = np.concatenate([square, rng.uniform(0.15, 0.85, (60, 2))])
    assert _corners(xy).tolist() == [True] * 4 + [False] * 60
    near = _corners(np.concatenate([xy, [[0.01, 0.0]]]))
    assert near.tolist() == [False, True, True, True] + [False] * 61
    line = np.c_[np.linspace(0.0, 1.0, 9), np.zeros(9)]
    assert _corners(line).all()


def test_a_hull_corner_with_a_near_neighbour_is_cross_validated_as_an_inner_ray():
    """The point-lit dome at a quarter false (seed 6, 64 cells): false highlight 5 meets the
    dome 0.05 from a true one, at a corner of a hull that stops short of the patch's edge. The
    fit without it misses it by 12.6 degrees, under the corners' 15 (CV_HULL_DEG), and it was
    kept: the only false one, 0.16 h worse than the clean scene. A fit without it is carried
    there from its neighbour, as to an inner ray: past CV_DEG it is rejected, and no true
    highlight is. False highlights 13 and 17, side by side, come back through the full-weight
    trial (``TRIAL_FLOOR_DEG``): each foresees the other, and the kept rays' misses move by
    0.006 degrees (paired median); 0.055 h worse than the clean scene (0.063 with every false
    highlight rejected)."""
    synthetic = make_scene("point-light", seed=6, outliers=0.25)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    rejected = set(solver.fit_report.rejected.tolist())
    assert 5 in rejected
    assert rejected <= set(np.flatnonzero(synthetic.outlier_mask).tolist())


def test_a_ray_that_bounds_the_hits_only_once_others_are_rejected_keeps_the_inner_limit():
    """Cross-validation passes with a square's corners (0-3), ray 4 just inside its right
    edge and 35 rays inside, each missed out of sample by a fixed angle: corners 1 and 2 by
    20 degrees, ray 4 by 12 (past CV_DEG, under CV_HULL_DEG), the rest by 1-3. A pass
    rejects at most two (CV_SHARE of 40): the first takes 1 and 2, which leaves ray 4 a
    corner of the hull of the hits kept. It is not one of the first pass's hull, so its
    limit stays the inner rays': the second pass rejects it. (The free-form patch at a tenth
    false, seed 701, 64 cells: true ray 3 rejected in the first pass left false ray 27 a
    corner, missed by 10.1 degrees in the next and kept, 0.475 h from the truth; 0.257 with
    it rejected, the clean scene 0.264.)"""
    rng = np.random.default_rng(5)
    xy = np.concatenate([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.95, 0.5]],
                         rng.uniform(0.1, 0.8, (35, 2))])
    miss = np.concatenate([[2.0, 20.0, 20.0, 2.0, 12.0], rng.uniform(1.0, 3.0, 35)])
    start = _seen_from_one_side(xy)
    start._around, start.progress = False, None
    start.excluded = np.zeros(len(xy), dtype=bool)
    start._ladder = lambda *args, **kwargs: None
    start._anchor = lambda level: None

    def misses_without(held, excluded, reference, resolution):
        start.excluded = excluded.copy()
        start.excluded[held] = True
        return miss

    start._misses_without = misses_without
    assert start._cross_validate(None, 32)
    assert np.flatnonzero(start.excluded).tolist() == [1, 2, 4]


def test_a_lone_miss_is_one_past_the_floor_and_twice_every_other():
    """Cross-validation's gap rule: the worst miss counts when it is past CV_FLOOR_DEG and
    CV_GAP times the next (rays not compared, negative, never count)."""
    lone = ImplicitStart._lone_miss
    assert lone(np.array([1.0, 7.8, 3.1, -1.0])).tolist() == [False, True, False, False]
    assert not lone(np.array([1.0, 7.8, 4.0])).any()  # within twice the next
    assert not lone(np.array([0.5, 4.5, 1.0])).any()  # under the floor
    assert lone(np.array([-1.0, 30.0, -1.0])).tolist() == [False, True, False]
    assert not lone(np.array([9.0])).any()


def test_a_spread_miss_is_past_the_floor_and_three_robust_sigmas_above_the_median():
    """Cross-validation's spread rule (seen all around): a miss counts past CV_FLOOR_DEG and
    REJECT_SIGMAS robust standard deviations above the median miss (rays not compared,
    negative, never count)."""
    spread = ImplicitStart._spread_miss
    base = [1.0, 1.2, 1.5, 0.8, 2.0, 1.6, 2.9, 1.1]
    # the median 1.55, 3 robust sigmas 2.22 above it: the limit is the floor, 5 degrees
    assert spread(np.array(base + [8.1, 5.9, -1.0])).tolist() == [False] * 8 + [True, True,
                                                                                False]
    assert not spread(np.array(base + [4.9])).any()  # under the floor
    wide = [1.0, 3.0, 5.0, 7.0, 9.0, 2.0, 4.0, 6.0, 8.0]  # with one more: the limit 16.6
    assert not spread(np.array(wide + [16.0])).any()
    assert spread(np.array(wide + [17.5])).tolist() == [False] * 9 + [True]
    assert not spread(np.array([9.0, -1.0])).any()


def test_a_pair_of_false_highlights_past_the_spread_of_the_misses_is_rejected_seen_all_around():
    """The blob at a quarter false (seed 501, 64 cells): fits made without each ray miss
    false highlights 32 and 24 by 8.1 and 5.9 degrees, the true ones by at most 2.9; under
    CV_DEG, and a pair (neither alone), both were kept, 0.34 h from the truth. Past 3 robust
    standard deviations of the misses, 32 is rejected (24 then met within 1.5 degrees, and
    kept): 0.24 h."""
    synthetic = make_scene("blob", seed=501, outliers=0.25)
    assert synthetic.outlier_mask[32]
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    rejected = set(solver.fit_report.rejected.tolist())
    assert 32 in rejected
    assert rejected <= set(np.flatnonzero(synthetic.outlier_mask).tolist())


def test_a_false_highlight_that_the_others_foresee_closely_is_rejected_under_cv_deg():
    """The blob at a tenth false (seed 1, 64 cells): fits made without each ray miss the true
    normals by at most 3.1 degrees (median 1.0), and false highlight 30 by 7.8, under CV_DEG,
    so it was kept (0.107 h worse than the clean scene). Missed by more than twice any other,
    it is rejected, and exactly the false highlights are."""
    synthetic = make_scene("blob", seed=1, outliers=0.1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert sorted(solver.fit_report.rejected.tolist()) == \
        np.flatnonzero(synthetic.outlier_mask).tolist()


@pytest.mark.parametrize("seed", [6, 10])
def test_a_sharp_feature_the_fits_without_it_miss_comes_back_in_a_trial(seed):
    """With 30 highlights on the free-form patch, the stiff passes reject the true highlights
    of its bump (5 and 6 on these seeds at 32 cells), and the fit made without them misses
    each by 18-33 degrees, past the return's 15. Tried back together, they make the bump and
    the kept rays' median miss falls, so they stay (without the trial they are reported
    false)."""
    synthetic = make_scene("freeform", seed=seed, highlights=30)
    result = ws.reconstruct(synthetic.scene(), resolution=32, iterations=20, device="cpu")
    assert result.rejected == []


def test_a_ray_that_would_come_back_alone_stays_out():
    """The blob at a quarter false (seed 5, 64 cells): of the ten false highlights tried back
    together, nine are missed by 34-76 degrees and the tenth (22) is met within 1.7 by the
    fit that bent to it, with the kept rays' median miss 3% lower, so it came back. One ray
    alone makes no feature: it stays out, and exactly the false highlights are rejected
    (0.132 h from the clean result end to end before, 0.050 after)."""
    synthetic = make_scene("blob", seed=5, outliers=0.25)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert sorted(solver.fit_report.rejected.tolist()) == \
        np.flatnonzero(synthetic.outlier_mask).tolist()


def _together(hits: np.ndarray, rays: list[int]) -> list[int]:
    """``ImplicitStart._together`` of ``rays`` among every ray, their hits at ``hits``."""
    start = ImplicitStart.__new__(ImplicitStart)
    start.m = len(hits)
    start.anchor = wp.array(np.asarray(hits, dtype=np.float32), dtype=wp.vec3)
    mask = np.zeros(len(hits), dtype=bool)
    mask[rays] = True
    return np.flatnonzero(start._together(mask, np.ones(len(hits), dtype=bool))).tolist()


def test_rays_come_back_together_only_where_no_kept_hit_lies_between_them():
    """Two hits are neighbours when no other hit lies inside the ball whose diameter joins
    them: a kept hit there parts them, one just outside it does not, and one ray alone never
    comes back."""
    pair = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    aside = [[0.5, 0.51, 0.0], [0.5, 0.0, -0.51], [3.0, 0.0, 0.0], [-1.5, 0.5, 0.0]]
    assert _together(np.array(pair + aside), [0, 1]) == [0, 1]
    assert _together(np.array(pair + aside + [[0.2, 0.3, 0.2]]), [0, 1]) == []
    assert _together(np.array(pair + aside), [0]) == []
    # three in a row: each neighbours the next, not the far one
    row = np.array(pair + [[2.0, 0.0, 0.0]] + aside[:1])
    assert _together(row, [0, 2]) == []
    assert _together(row, [0, 1, 2]) == [0, 1, 2]


def test_false_highlights_tried_back_apart_from_each_other_stay_out():
    """The blob at a tenth false (seed 201, 64 cells): the robust passes reject exactly the
    four false highlights, and the trial puts them back. The fit bends to three of them,
    meets them within 1.0-1.7 degrees, and the kept rays' median miss hardly moves, so they
    stayed; cross-validation, made from fits that had bent to them, missed two by 5.0 and
    9.0 only. Kept, the blob was 0.132 h worse than the clean scene. Each lies among kept
    rays, 2.9-3.0 times the hits' median spacing from the next, so none makes a feature
    with another: they stay out (0.009 h worse than the clean scene)."""
    synthetic = make_scene("blob", seed=201, outliers=0.1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert sorted(solver.fit_report.rejected.tolist()) == \
        np.flatnonzero(synthetic.outlier_mask).tolist()


def test_a_feature_whose_every_ray_comes_back_is_kept_within_the_median_error():
    """The free-form patch, seed 402 (the bump on a crest of the waves), clean: the robust
    passes reject the bump's 6 rays, and the trial that puts them back meets every one
    within 1.2 degrees, each beside another; the kept rays' median miss moved 0.344 -> 0.357
    degrees (its standard error 0.057; paired, their misses moved by -0.005 in the median),
    and the trial was refused: cross-validation rejected 2 more, and the patch came out
    0.75 h from the truth with the bump cut off. A trial whose every ray stays may move the
    median by its standard error: none is rejected, 0.24 h."""
    synthetic = make_scene("freeform", seed=402)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert len(solver.fit_report.rejected) == 0


def test_a_feature_the_robust_weights_would_drop_is_tried_back_at_full_weight():
    """The free-form patch, seed 402, a tenth false: the bump keeps 5 true rays (19, 23, 28,
    53, 55), and the robust passes reject 19 and 53. Under the robust weights a trial met 19
    and missed 53 by 27 degrees (a fit without the bump misses its rays past the weights'
    limit), both stayed out, cross-validation then rejected the other three, and the patch
    was 0.94 h from the truth. When the robust trial takes none, the rays are tried at full
    weight: every bump ray is met, foreseen by the others, and stays."""
    synthetic = make_scene("freeform", seed=402, outliers=0.1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert set(solver.fit_report.rejected.tolist()).isdisjoint({19, 23, 28, 53, 55})


def test_false_highlights_side_by_side_stay_out_unless_each_foresees_the_other():
    """The free-form patch, seed 2, a quarter false: false highlights 18 and 28 neighbour each
    other, and tried back at full weight both are met (within 2.3 and 5.6 degrees), the kept
    median miss within its standard error. A fit with one but without the other misses it
    (``ImplicitStart._foreseen``), so both stay out (taken, the patch was 0.32 h from the
    truth instead of 0.18)."""
    synthetic = make_scene("freeform", seed=2, outliers=0.25)
    assert synthetic.outlier_mask[[18, 28]].all()
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert {18, 28} <= set(solver.fit_report.rejected.tolist())


def _rejected_true_and_false(synthetic) -> tuple[int, int, str | None]:
    """How many true and how many false highlights the start rejects, at resolution 64, and
    the prior of its grid fit."""
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    rejected = np.zeros(synthetic.outlier_mask.shape, dtype=bool)
    rejected[solver.fit_report.rejected] = True
    return (int((rejected & ~synthetic.outlier_mask).sum()),
            int((rejected & synthetic.outlier_mask).sum()), solver.fit_report.prior)


def test_cross_validation_goes_on_until_no_ray_is_missed():
    """The free-form patch, seed 302, a quarter false: the robust passes reject 3 of the 15
    false highlights, and cross-validation starts from a fit that the other 12 bend, missing
    29 of 58 rays out of sample, true ones worst. Stopped after 8 passes, it had rejected 14
    true highlights and 10 false, and the patch was 1.05 h from the truth. Its passes now end
    where none is missed (the tenth); the true ones come back, and 9 false stay out."""
    true, false, _ = _rejected_true_and_false(make_scene("freeform", seed=302, outliers=0.25))
    assert true <= 1 and false >= 9


def test_rays_the_robust_passes_rejected_are_tried_back_apart_from_the_false_ones():
    """The free-form patch, seed 23, a quarter false: the robust passes reject 7 true rays of
    a steep region (and 2 false), which stay out as long as false highlights bend the fit;
    cross-validation then rejects 12 false and 3 true. Tried back all together, the false
    ones were met too, the kept median grew, none came back, and with 10 true rays out the
    verdict refused the patch. Tried back first by themselves, from the fit without the false
    ones, the steep region's rays come back, then most of those cross-validation rejected: 3
    true rays stay out (2 before the hull of the first pass bounded the corners: 0.339 h from
    the truth against 0.336), and 12 false."""
    true, false, _ = _rejected_true_and_false(make_scene("freeform", seed=23, outliers=0.25))
    assert true <= 3 and false >= 11


def test_two_grid_fits_are_told_apart_by_their_points_when_the_rays_cannot():
    """The free-form patch, seed 17, a tenth false: a ring torus meets more normal lines than
    the quadric, and the grid fit about it keeps 5 of the 6 false highlights and meets more
    kept rays (55 to 54); by that count it was taken, 0.42 h from the truth. The points left
    out one at a time lie 0.26 voxel from its fits in the median and 0.08 from the quadric's:
    the quadric's fit is taken, 3 false highlights rejected, 0.19 h (clean 0.085)."""
    _, false, prior = _rejected_true_and_false(make_scene("freeform", seed=17, outliers=0.1))
    assert prior == "quadric"
    assert false >= 3


def test_better_fit_lets_the_points_decide_only_when_far_apart():
    """The points' distances out of sample decide between two fits when their medians are
    more than PRIOR_POINTS_RATIO apart, whichever explains more rays; nearer, or with too few
    points on either side, the rays decide."""
    from warpspec.implicit import PRIOR_POINTS_RATIO, _better_fit

    near = np.array([0.03, 0.31, 0.49, 0.08, 0.06])
    far = near * (PRIOR_POINTS_RATIO * 1.05)
    close = near * (PRIOR_POINTS_RATIO * 0.95)
    more, fewer = (55, -3.0), (54, -3.0)
    assert _better_fit((fewer, near), (more, far))
    assert not _better_fit((more, far), (fewer, near))
    assert _better_fit((more, close), (fewer, near))
    assert not _better_fit((fewer, near), (more, close))
    assert not _better_fit((fewer, near), (more, None))
    assert _better_fit((more, None), (fewer, near))
    assert not _better_fit((more, near), (more, near))


@pytest.mark.parametrize("seed", [11, 47])
def test_a_bump_that_a_quadric_start_lets_go_makes_the_grid_fit_the_start(seed):
    """The clean point-lit dome: its quadric meets 23-24 of 30 normals within 3 degrees and
    misses the bumps' 6-7 by more than 10, as false ones are missed, so it was the start,
    0.365 and 0.427 h from the truth end to end. Fitted without them, the grid fit about the
    quadric meets them all (a fit made without a ray foresees it), and it is the start, every
    ray kept: 0.104 and 0.125 h."""
    synthetic = make_scene("point-light", seed=seed)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "grid"
    assert solver.fit_report.rejected.size == 0


@pytest.mark.parametrize("name, seed, outliers, shape", [
    ("ellipsoid-around", 0, 0.1, "quadric"), ("sphere-around", 2, 0.1, "quadric"),
    ("point-light", 20, 0.1, "grid"), ("point-light", 12, 0.1, "grid")])
def test_false_highlights_a_quadric_start_lets_go_are_no_feature(name, seed, outliers, shape):
    """A quadric start that lets go false highlights stays the start: a fit made without them
    misses them too (the ellipsoid's three, side by side on its hits, and the sphere's pair,
    which the trial's fit bends to and meets). On the point-lit dome a tenth false (seed 20)
    the quadric lets go the bump's six true highlights and the three false: the fit without
    them meets the six, and the grid fit is the start with exactly the false ones out. Seed
    12 a tenth false: one true highlight of each bump comes back, far apart, and the fits
    made without each meet it (0.266 h as the quadric, 0.183 now, 0.125 clean)."""
    synthetic = make_scene(name, seed=seed, outliers=outliers)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == shape
    assert solver.fit_report.rejected.tolist() == np.flatnonzero(synthetic.outlier_mask).tolist()


def test_true_rays_tried_back_may_grow_a_tiny_median_by_a_floor():
    """The point-lit dome, seed 500, clean: the first robust pass rejects true rays 9, 21 and
    25. Tried back at full weight all three are met within 1.1 degrees, and the kept median
    grows 0.113 -> 0.136 degrees, beyond its standard error (0.018) but within the refit's
    path (``TRIAL_FLOOR_DEG``); the others foresee each, and all three come back (refused,
    the dome was 0.22 h from the truth instead of 0.11)."""
    synthetic = make_scene("point-light", seed=500)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.rejected.size == 0


def test_median_error_is_the_spread_of_the_median_over_samples():
    """The standard error of the median is sqrt(pi / 2) sigma / sqrt(n) for normal data: over
    4,000 samples of 101, the medians' spread matches the mean estimate within 5% (without
    the sqrt(pi / 2) it is 20% short)."""
    from warpspec.implicit import median_error

    rng = np.random.default_rng(3)
    samples = rng.normal(1.0, 0.7, size=(4000, 101))
    spread = float(np.std(np.median(samples, axis=1)))
    estimate = float(np.mean([median_error(x) for x in samples]))
    assert abs(estimate / spread - 1.0) < 0.05
    assert median_error(np.zeros(0)) == 0.0
    assert median_error(np.full(9, 2.5)) == 0.0


def test_robust_sigma_is_the_standard_deviation_despite_a_fifth_false():
    """1.4826 median(|x|) of normal residuals about zero is their sigma (within 3% over
    20,000); a fifth replaced by residuals 50 sigma off moves it by the median's shift
    alone (about 30%), where the root mean square grows twentyfold."""
    from warpspec.quadric import robust_sigma

    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 0.4, 20000)
    assert abs(robust_sigma(x) / 0.4 - 1.0) < 0.03
    assert robust_sigma(np.abs(x)) == robust_sigma(x)
    x[:4000] = 20.0
    assert robust_sigma(x) / 0.4 < 1.4
    assert float(np.sqrt(np.mean(x ** 2))) / 0.4 > 20.0
    assert robust_sigma(np.zeros(0)) == 0.0


def test_mesh_pieces_far_from_the_data_are_dropped():
    grid = Grid(origin=np.zeros(3), spacing=0.1, shape=(31, 31, 31))
    x, y, z = grid.coordinates()
    near = np.sqrt((x - 0.8) ** 2 + (y - 1.5) ** 2 + (z - 1.5) ** 2) - 0.4
    far = np.sqrt((x - 2.4) ** 2 + (y - 1.5) ** 2 + (z - 1.5) ** 2) - 0.3
    phi = np.minimum(near, far)
    v, f = triangulate(phi, grid)
    anchors = np.array([[0.8, 1.5, 1.9], [0.4, 1.5, 1.5]])
    kept_v, kept_f = supported_components(v, f, anchors, radius=0.3)
    assert len(kept_f) < len(f)
    assert np.all(np.abs(np.linalg.norm(kept_v - [0.8, 1.5, 1.5], axis=1) - 0.4) < 0.02)
    assert not is_open(kept_f)


@pytest.mark.parametrize("seed", range(6))
def test_mesh_components_match_a_graph_library_on_scrambled_meshes(seed):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(seed)
    parts, offset = [], 0
    for _ in range(int(rng.integers(1, 5))):
        sphere = trimesh.creation.icosphere(subdivisions=int(rng.integers(0, 4)))
        parts.append(sphere.faces + offset)
        offset += len(sphere.vertices)
    n = offset + int(rng.integers(0, 4))  # vertices no face uses are pieces of their own
    order = rng.permutation(n)
    faces = order[np.concatenate(parts)][rng.permutation(sum(len(p) for p in parts))]
    if seed % 2:  # random triangles: long chains, pieces of any shape
        faces = rng.integers(0, n, size=(n // 2, 3))
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    got_count, got_label = vertex_components(n, faces)
    assert got_count == count
    assert np.array_equal(got_label, label)


def test_specks_of_the_level_set_are_dropped_even_beside_the_data():
    grid = Grid(origin=np.zeros(3), spacing=0.1, shape=(31, 31, 31))
    x, y, z = grid.coordinates()
    body = np.sqrt((x - 1.5) ** 2 + (y - 1.5) ** 2 + (z - 1.5) ** 2) - 0.8
    speck = np.sqrt((x - 2.54) ** 2 + (y - 1.52) ** 2 + (z - 1.53) ** 2) - 0.06  # a voxel
    v, f = triangulate(np.minimum(body, speck), grid)
    anchors = np.array([[2.3, 1.5, 1.5], [1.5, 1.5, 2.3]])  # the first beside the speck
    kept_v, kept_f = supported_components(v, f, anchors, radius=0.3)
    assert len(kept_f) == len(f)  # near the data: kept without a least size
    kept_v, kept_f = supported_components(v, f, anchors, radius=0.3, min_extent=0.2)
    assert 0 < len(f) - len(kept_f) < 50
    assert np.all(np.abs(np.linalg.norm(kept_v - 1.5, axis=1) - 0.8) < 0.02)
    assert not is_open(kept_f)


def test_open_surface_is_cropped_to_the_hull_of_the_data():
    grid = Grid(origin=np.zeros(3), spacing=0.1, shape=(31, 31, 31))
    _, _, z = grid.coordinates()
    v, f = triangulate(z - 1.5, grid)  # a plane through the whole domain
    assert is_open(f)
    anchors = np.array([[1, 1, 1.5], [2, 1, 1.5], [1, 2, 1.5], [2, 2, 1.45], [1.5, 1.5, 1.55]])
    kept_v, kept_f = crop_to_data_hull(v, f, anchors, margin=0.1)
    centres = kept_v[kept_f].mean(axis=1)
    assert centres[:, :2].min() > 0.85 and centres[:, :2].max() < 2.15
    assert len(kept_f) < len(f) / 3


def test_the_faces_behind_the_data_are_those_no_camera_looks_at_far_from_it():
    """A unit sphere seen from one camera at (0, 0, 3): it sees a face of normal ``n`` from
    the front where ``3 n_z > 1``. With the anchors on the cap ``n_z > 0.9``, everything below
    ``n_z = 1/3`` is one piece turned away, 45 degrees of arc from the data, and dropped; the
    front ``+z`` alone drops the lower hemisphere; an anchor on the back keeps it all."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    n_z = sphere.face_normals[:, 2]
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 3)) * [0.2, 0.2, 0.0] + [0.0, 0.0, 1.0]
    anchors = a / np.linalg.norm(a, axis=1, keepdims=True)
    anchors = anchors[anchors[:, 2] > 0.9]
    camera = np.array([[0.0, 0.0, 3.0]])
    behind = faces_behind(v, f, anchors, radius=0.1, front=[0, 0, 1], viewpoints=camera)
    centres_z = v[f].mean(axis=1)[:, 2] / np.linalg.norm(v[f].mean(axis=1), axis=1)
    assert np.all(behind[n_z < 0.3]) and not np.any(behind[n_z > 0.36])
    assert np.all(centres_z[~behind] > 0.3)
    # the front alone: the lower hemisphere, in either sense of the windings
    alone = faces_behind(v, f, anchors, radius=0.1, front=[0, 0, 1])
    assert np.array_equal(alone, n_z <= 0.0)
    flipped = faces_behind(v, f[:, ::-1], anchors, radius=0.1, front=[0, 0, -1])
    assert np.array_equal(flipped, alone)
    # the windings reversed, their sense told by the anchors seen from the camera
    seen = (anchors, np.repeat(camera, len(anchors), axis=0))
    assert np.array_equal(faces_behind(v, f[:, ::-1], anchors, radius=0.1, front=[0, 0, 1],
                                       viewpoints=camera, seen=seen), behind)
    # an anchor on the back: the piece turned away reaches the data and is kept whole
    back = np.vstack([anchors, [[0.0, 0.0, -1.0]]])
    assert not faces_behind(v, f, back, radius=0.1, front=[0, 0, 1], viewpoints=camera).any()


@pytest.mark.parametrize("grow", [2.0, 3.0])
def test_the_octant_in_a_wide_domain_loses_the_sphere_behind_it(grow):
    """The paper's octant in a domain 2 and 3 times as wide about its centre: the fit is the
    unit sphere, whose back lies inside the data's hull seen along its normal (in the wider
    domain the whole sphere, closed). Kept whole it was 4.7 and 6.7 h from the truth over
    that hull; the faces behind the data dropped, the octant is as close as in its own."""
    data = make_scene("octant").scene().to_dict()
    lo, hi = np.array(data["domain"]["min"]), np.array(data["domain"]["max"])
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    data["domain"] = {"min": list(centre - grow * half), "max": list(centre + grow * half)}
    from warpspec.evaluate import evaluate, truth_region

    synthetic = make_scene("octant")
    region = truth_region(synthetic.truth_points, synthetic.points)
    solver = ws.Reconstructor(ws.Scene.from_dict(data), resolution=64, device="cpu")
    solver.run(solver.default_iterations)
    h = solver.grid.spacing

    def scored(mesh):
        return evaluate(mesh, synthetic.truth_mesh(), spacing=h, region=region, samples=5000)

    whole = solver.result(crop=False)
    assert scored(whole.mesh).accuracy.mean > 2.0 * h
    result = solver.result()
    ev = scored(result.mesh)
    assert ev.accuracy.mean < 0.05 * h and ev.completeness.mean < 0.05 * h
    assert is_open(result.faces)
    assert result.verdict.supported


def _cylinder_mesh(radius):
    """A whole cylinder of axis (0, 0, 1) through (0.3, -0.2), heights -1..1, angle 0 on x."""
    mesh = Cylinder([0.3, -0.2, 0.0], [0.0, 0.0, 1.0], radius, reference=[1.0, 0.0, 0.0],
                    extent=(-1.0, 1.0)).mesh(sections=180)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def test_a_patch_bending_round_is_cropped_along_itself_not_by_chords():
    """Anchors on 220 degrees of a cylinder, sparse along its top rim: the crop follows the
    patch (arc 0..220 degrees, heights within the anchors, each grown by the margin) and keeps
    the rim between rim anchors, where the 3-D hull's chords cut 0.2 under it."""
    r, margin = 0.5, 0.05
    v, f = _cylinder_mesh(r)
    rng = np.random.default_rng(3)
    ang = np.radians(np.concatenate([[0, 0, 220, 220, 110], rng.uniform(10, 210, 20),
                                     [40, 180]]))
    z = np.concatenate([[-0.8, 0.8, -0.8, 0.8, 0.0], rng.uniform(-0.6, 0.5, 20), [0.8, 0.8]])
    normals = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], -1)
    hits = np.array([0.3, -0.2, 0.0]) + r * normals + np.outer(z, [0, 0, 1])
    kept_v, kept_f = crop_to_unwrapped_hull(v, f, hits, hits, normals, margin=margin)
    c = kept_v[kept_f].mean(axis=1)
    a = np.degrees(np.mod(np.arctan2(c[:, 1] + 0.2, c[:, 0] - 0.3), 2 * np.pi))
    a = np.where(a > 290, a - 360, a)  # the cut lies in the empty arc, 220..360
    slack = np.degrees(margin / r) + 2.0  # the margin as an angle, and a face's width
    assert a.min() > -slack and a.max() < 220 + slack
    assert c[:, 2].min() > -0.8 - margin - 0.05 and c[:, 2].max() < 0.8 + margin + 0.05
    rim = (np.abs(a - 110) < 10) & (c[:, 2] > 0.7)  # between the rim anchors at 40 and 180
    assert rim.sum() > 10
    hv, hf = crop_to_data_hull(v, f, hits, margin=margin)
    hc = hv[hf].mean(axis=1)
    ha = np.degrees(np.mod(np.arctan2(hc[:, 1] + 0.2, hc[:, 0] - 0.3), 2 * np.pi))
    assert not np.any((np.abs(ha - 110) < 10) & (hc[:, 2] > 0.7))


def test_anchors_all_round_an_axis_are_not_unwrapped():
    v, f = _cylinder_mesh(0.5)
    ang = np.radians(np.arange(0, 360, 20.0))
    normals = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], -1)
    hits = np.array([0.3, -0.2, 0.0]) + 0.5 * normals + np.outer(np.resize([-0.5, 0.5], 18),
                                                                 [0, 0, 1])
    assert crop_to_unwrapped_hull(v, f, hits, hits, normals, margin=0.05) is None
    # one of them gone leaves a 40 degree arc empty: cut there, and nowhere else
    kept_v, kept_f = crop_to_unwrapped_hull(v, f, hits[1:], hits[1:], normals[1:], margin=0.05)
    c = kept_v[kept_f].mean(axis=1)
    a = np.degrees(np.mod(np.arctan2(c[:, 1] + 0.2, c[:, 0] - 0.3), 2 * np.pi))
    counts = np.histogram(a, bins=36, range=(0, 360))[0]
    assert counts[2:-2].min() > 0 and counts[[0, -1]].max() == 0
    assert np.allclose(np.sort(c[:, 2])[[0, -1]], [-0.55, 0.55], atol=0.06)


def _scored(synthetic, mesh, h: float):
    """``mesh`` against the truth, over the hull of the inliers' true hits and the points."""
    from warpspec.evaluate import evaluate, truth_region

    region = truth_region(synthetic.truth_points[synthetic.inliers], synthetic.points)
    return evaluate(mesh, synthetic.truth_mesh(sections=64), spacing=h, region=region,
                    samples=5000)


@pytest.mark.parametrize("seed", [0, 3])
def test_false_highlights_on_a_wrap_leave_its_crop_as_the_clean_one(seed):
    """A quarter of the wrap's highlights false: the crop, in the patch's own coordinates,
    still reaches its rims. In the hulls of the anchors (3-D and 2-D) the chords between the
    fewer true hits cut into the top rim, and the truth was 0.29 h (seed 0) and 0.11 h
    (seed 3) from the mesh instead of 0.04 and 0.03 clean."""
    comp = []
    for outliers in (0.0, 0.25):
        synthetic = make_scene("wrap", outliers=outliers, seed=seed)
        result = ws.reconstruct(synthetic.scene(), resolution=64, device="cpu")
        h = result.grid.spacing
        ev = _scored(synthetic, result.mesh, h)
        comp.append(ev.completeness.mean / h)
        assert ev.accuracy.mean < 0.1 * h
    assert max(comp) < 0.05 and abs(comp[1] - comp[0]) < 0.02


def test_a_tube_seen_all_around_is_not_cut_open_where_false_highlights_were_rejected():
    """The bottle under lamps, a quarter false, seed 200: the highlights rejected as false left
    95 degrees of the kept normals empty, and a rule that cropped any empty arc over 90 degrees
    cut the tube open there (Euler 1, the truth 1.23 h from the mesh). Its cameras stand all
    round (their arcs within 1.14 times of each other): the tube stays whole."""
    synthetic = make_scene("bottle-lamps", outliers=0.25, seed=200)
    result = ws.reconstruct(synthetic.scene(), resolution=64, device="cpu")
    assert sorted(r["index"] for r in result.rejected) == np.flatnonzero(
        synthetic.outlier_mask).tolist()  # the case the test is about: every false one out
    mesh = result.mesh.copy()
    mesh.merge_vertices()
    assert mesh.euler_number == synthetic.euler
    h = result.grid.spacing
    ev = _scored(synthetic, mesh, h)
    assert ev.completeness.mean < 0.1 * h and ev.accuracy.mean < 0.1 * h


def test_conjugate_gradients_solve_the_normal_equations():
    """The device CG meets the dense solution of the same least-squares problem."""
    import warpspec.implicit as I

    grid = Grid(origin=np.zeros(3), spacing=0.25, shape=(6, 6, 6))
    level = I._Level(grid, wp.get_device("cpu"))
    rng = np.random.default_rng(5)
    xs = rng.uniform(0.5, 4.5, size=(12, 3))  # the level's voxels
    normals = rng.normal(size=(12, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    ys = rng.uniform(0.5, 4.5, size=(3, 3))
    f32 = np.float32
    grads = (wp.array(xs.astype(f32), dtype=wp.vec3), wp.array(np.ones(12, f32), dtype=float))
    nrm = wp.array(normals.astype(f32), dtype=wp.vec3)
    values = (wp.array(ys.astype(f32), dtype=wp.vec3),
              wp.array(np.full(3, 5.0, f32), dtype=float))
    level.f.zero_()
    level.solve(grads, nrm, values, 3000)
    fitted = level.f.numpy().ravel().astype(np.float64)
    # the dense matrix, column by column, and the right-hand side (prev = 0: rhs is G^T N)
    n = grid.size
    A = np.zeros((n, n))
    for c in range(n):
        e = np.zeros(n, dtype=f32)
        e[c] = 1.0
        level.p.assign(wp.array(e.reshape(grid.shape), dtype=float))
        level.apply(level.p, level.ap, grads, values)
        A[:, c] = level.ap.numpy().ravel()
    level.f.zero_()
    level.solve(grads, nrm, values, 0)  # assembles rhs for f_prev = 0 without iterating
    b = level.rhs.numpy().ravel().astype(np.float64)
    exact = np.linalg.solve(0.5 * (A + A.T), b)
    assert np.allclose(A, A.T, atol=1e-3 * np.abs(A).max())
    assert np.abs(fitted - exact).max() < 1e-3 * np.abs(exact).max()


def test_a_dense_point_cloud_pulls_as_the_sparse_one_does():
    """20,000 points on the octant (a structure-from-motion cloud): the same surface as with
    its three corners, not a level set flattened by a summed Gaussian."""
    import json
    from pathlib import Path

    data = json.loads((Path(__file__).resolve().parents[1] / "examples" / "scenes" /
                       "octant.json").read_text())
    rng = np.random.default_rng(0)
    cloud = np.abs(rng.normal(size=(20_000, 3)))
    cloud /= np.linalg.norm(cloud, axis=1, keepdims=True)
    data["points"] = cloud.tolist()
    result = ws.reconstruct(ws.Scene.from_dict(data), resolution=24, iterations=30,
                            device="cpu")
    assert result.verdict.supported and result.verdict.normal_error_deg < 2.0
    err = np.abs(np.linalg.norm(result.vertices, axis=1) - 1.0) / result.grid.spacing
    assert err.mean() < 0.05


def test_the_set_up_reports_its_stages():
    said: list[str] = []
    ws.Reconstructor(make_scene("freeform").scene(), resolution=32, device="cpu",
                     progress=said.append)
    assert said[0].startswith("a quadric fitted to 60 rays and 5 points")
    assert "grid 16 of 16, 32" in said and "grid 32 of 16, 32" in said
    assert "cross-validation pass 1 of 14 (60 folds, grid 32)" in said


def test_fill_pockets_removes_sealed_regions_and_keeps_the_sheet(device):
    from warpspec.implicit import fill_pockets

    n = 20
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for _ in range(3)), indexing="ij")
    sheet = k - 9.5  # a plane: each side touches the boundary
    field = sheet.copy()
    # a bubble of phi > 0 under the sheet, one of phi < 0 above it
    up = np.sqrt((i - 6) ** 2 + (j - 6) ** 2 + (k - 4) ** 2) < 2.5
    down = np.sqrt((i - 13) ** 2 + (j - 12) ** 2 + (k - 15) ** 2) < 2.5
    field[up] = 1.0
    field[down] = -1.0
    phi = _field(field, device)
    assert fill_pockets(phi, both=True) == 2
    assert np.array_equal(phi.numpy() > 0, sheet > 0)
    # seen all around: only the sealed pocket of phi > 0 (a cavity) goes; a closed object
    # (a sealed region of phi < 0) stays
    phi = _field(field, device)
    assert fill_pockets(phi, both=False) == 1
    assert np.array_equal(phi.numpy() > 0, (sheet > 0) & ~down)
    # nothing sealed: nothing changes
    phi = _field(sheet, device)
    assert fill_pockets(phi, both=True) == 0
    assert np.array_equal(phi.numpy(), sheet.astype(np.float32))


def test_cameras_surround_only_when_no_half_space_holds_them():
    """A camera a little below the horizon of a patch seen from above does not surround it
    (the mean direction would say it does); rings all around, and a tube's rings, do."""
    from warpspec.implicit import surrounds

    az = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    dome = np.stack([np.cos(az), np.sin(az), np.full(12, 0.4)], axis=1)
    dome = np.concatenate([dome, [[0.9, 0.0, -0.1], [0.0, 0.0, 1.0]]])
    dome = np.concatenate([dome[:12] * [0.2, 0.2, 1.0], dome[12:]])  # mostly overhead
    dome /= np.linalg.norm(dome, axis=1, keepdims=True)
    m = dome.sum(axis=0) / np.linalg.norm(dome.sum(axis=0))
    assert np.min(dome @ m) < 0.0  # the mean direction's test would call it surrounded
    assert not surrounds(dome)
    ring = np.stack([np.cos(az), np.sin(az), np.full(12, -0.1)], axis=1)
    assert surrounds(np.concatenate([ring, ring * [1.0, 1.0, -3.0]]))
    assert not surrounds(np.zeros((0, 3)))
    # a free-form patch whose lowest cameras stand a little below its horizon
    scene = make_scene("freeform", seed=6).scene()
    grid = Grid.from_bounds(*scene.domain, resolution=16)
    assert first_guess(scene, grid, initial_plane(scene, grid)).kind == "plane"


def test_surrounds_agrees_with_the_linear_program_on_random_cameras():
    """The shortcut (a perceptron's half-space) never changes the answer: caps of directions
    from narrow to wider than a hemisphere, against scipy's linprog itself."""
    from scipy.optimize import linprog

    from warpspec.implicit import surrounds

    rng = np.random.default_rng(7)
    answers = []
    for _ in range(120):
        count = int(rng.integers(3, 40))
        centre = rng.standard_normal(3)
        u = centre / np.linalg.norm(centre) + rng.uniform(0.2, 2.5) * rng.standard_normal(
            (count, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        fit = linprog(np.zeros(3), A_ub=-u, b_ub=-np.ones(count),
                      bounds=[(None, None)] * 3, method="highs")
        assert surrounds(u) == (fit.status == 2)
        answers.append(fit.status == 2)
    assert 20 < sum(answers) < 100  # both answers are tested


def test_a_ray_entering_the_box_inside_a_quadric_and_again_later_is_entered_from_inside():
    # q = -x^2 + y^2 + z^2 + 0.25 (its inside, q <= 0, two caps: |x| >= 0.5 on the axis):
    # along +x from x = -3 a ray leaves the inside at x = -0.5 and enters again at 0.5
    caps = Q.Quadric(np.array([-1.0, 1.0, 1.0, 0, 0, 0, 0, 0, 0, 0.25]), np.zeros(3), 1.0)
    origins = np.array([[-3.0, 0.0, 0.0], [-3.0, 3.0, 0.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    far = caps.entered_from_inside(origins, dirs, np.full(3, -1.0), np.full(3, 4.0))
    assert far.tolist() == [True, False]  # the second, at y = 3, enters once, at x = 3.04
    near = caps.entered_from_inside(origins, dirs, np.array([0.0, -1.0, -1.0]), np.full(3, 4.0))
    assert near.tolist() == [False, False]  # the box begins between the caps, outside
    ball = Q.sphere(np.zeros(3), 1.0, frame_centre=np.zeros(3), scale=1.0)
    # the box cuts the ball: the ray enters it inside, but only leaves it
    assert not ball.entered_from_inside(origins[:1], dirs[:1], np.array([-0.5, -2, -2]),
                                        np.full(3, 2.0)).any()


def test_the_octant_turned_in_a_wider_domain_is_the_sphere_the_cameras_see_from_outside():
    """Turned (a fixed random turn), the octant's box round the turned domain holds more of
    the sphere. The quadric fitted from the plane met every normal within 3 degrees (the
    median 0.4), but 4 of the 24 rays reached their hits through its inside: taken as the
    first of equals, the hits lay 0.17-1.2 from the centre and the verdict refused it. The
    spheres' fits meet every normal exactly, and no ray enters them from inside."""
    from .helpers import turned

    w, x, y, z = np.random.default_rng(1).normal(size=4) / np.linalg.norm(
        np.random.default_rng(1).normal(size=4))
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    data = turned(make_scene("octant").scene().to_dict(), R)
    result = ws.reconstruct(ws.Scene.from_dict(data), resolution=64, device="cpu")
    assert result.verdict.supported
    h = result.grid.spacing
    assert np.all(np.abs(np.linalg.norm(result.hits, axis=1) - 1.0) < 0.1 * h)
    v = result.vertices[np.linalg.norm(result.vertices - R @ np.ones(3) / np.sqrt(3),
                                       axis=1) < 0.8]
    assert np.abs(np.linalg.norm(v, axis=1) - 1.0).mean() < 0.05 * h


def test_columns_sweep_the_box_and_find_a_second_sheet():
    from warpspec.implicit import columns

    lo, hi = np.array([-1.0, -1.0, -0.5]), np.array([1.0, 1.0, 0.5])
    origins, dirs = columns(np.array([0.0, 0.0, 1.0]), lo, hi, count=9)
    assert origins.shape == (81, 3) and np.allclose(dirs, [0.0, 0.0, -1.0])
    assert np.all(origins[:, 2] > hi[2])
    # the lines cover the box's shadow: its corners lie inside the lines' span
    assert origins[:, 0].min() <= lo[0] and origins[:, 0].max() >= hi[0]
    # a sphere of radius 0.3 inside the box: both of its sheets are crossed by the
    # centre line, and no line crosses the plane z = 0 twice
    ball = Q.sphere(np.zeros(3), 0.3, frame_centre=np.zeros(3), scale=1.0)
    flat = Q.plane(np.zeros(3), np.array([0.0, 0.0, 1.0]), frame_centre=np.zeros(3), scale=1.0)
    assert ball.sheets_crossed(origins, dirs, lo, hi) == 2
    assert flat.sheets_crossed(origins, dirs, lo, hi) == 1


def test_a_one_sided_start_has_no_second_sheet():
    # free-form seed 2 with 45 highlights: its general quadric closes a second sheet in two
    # corners of the domain, which no ray meets; the fit used to follow it into a fold 3 voxels
    # deep over half the patch
    syn = make_scene("freeform", outliers=0.25, seed=2)
    data = syn.scene().to_dict()
    data["specularities"] = [s for s, ok in zip(data["specularities"], syn.inliers,
                                                strict=True) if ok]
    result = ws.reconstruct(ws.Scene.from_dict(data), resolution=32, iterations=1)
    crossings = (np.diff(np.sign(result.phi), axis=2) != 0).sum(axis=2)
    assert np.all(crossings == 1)


@pytest.mark.parametrize(("span", "outliers"), [(185.0, 0.0), (210.0, 0.0), (330.0, 0.25)])
def test_a_patch_that_turns_further_than_a_third_of_a_turn_is_cropped_to_its_data(span,
                                                                                outliers):
    # at 185 degrees the highlights' normals span 166, inside a half-space: the fitted cylinder
    # went on round behind the data, 3 voxels from the truth on average and 25 at worst; at
    # 330 with a quarter false, the kept normals leave a 63-degree arc empty, no wider than
    # 1.8 times the next, and the patch was closed into a tube (0.99 voxel off on average)
    synthetic = make_scene("wrap", span=span, outliers=outliers)
    result = ws.reconstruct(synthetic.scene(), resolution=64, device="cpu")
    h = result.grid.spacing
    ev = _scored(synthetic, result.mesh, h)
    assert ev.accuracy.mean < 0.2 * h and ev.accuracy.max < 2.5 * h
    assert ev.completeness.mean < 0.2 * h
    assert result.mesh.euler_number == 1


def test_the_widest_empty_arcs_between_directions():
    from warpspec.solver.reconstructor import _widest_arcs

    a = np.radians([0.0, 10.0, 30.0, 300.0])
    widest, next_widest = _widest_arcs(np.cos(a), np.sin(a))
    assert widest == pytest.approx(270.0) and next_widest == pytest.approx(60.0)
    # the arc across the cut at +-180 degrees counts like any other
    a = np.radians([170.0, -170.0, 0.0])
    assert _widest_arcs(np.cos(a), np.sin(a)) == pytest.approx((170.0, 170.0))


def test_the_wrap_scene_takes_a_span():
    with pytest.raises(ws.SceneError, match="span"):
        make_scene("wrap", span=20.0)
    normals = make_scene("wrap", span=150.0).truth_normals
    assert np.degrees(np.arccos(np.clip(normals @ normals.T, -1, 1))).max() < 150.0


def test_a_torus_seen_only_from_above_is_still_a_torus():
    """Cameras 15-75 degrees above the torus' plane only: a half-space holds them (the plane
    guess), yet they see it from every side, and the ring torus is tried and taken."""
    synthetic = make_scene("torus")
    scene, t = synthetic.scene(), synthetic.surface
    rel = scene.camera_centres() - t.centre
    elevation = np.degrees(np.arcsin(rel @ t.axis / np.linalg.norm(rel, axis=1)))
    keep = (elevation > 15.0) & (elevation < 75.0)
    data = scene.to_dict()
    data["specularities"] = [s for s in data["specularities"] if keep[s["camera"]]]
    solver = ws.Reconstructor(ws.Scene.from_dict(data), resolution=32, device="cpu")
    assert solver.fit_report.guess == "plane"
    assert solver.fit_report.shape == "torus"
    solver.run(20)
    result = solver.result()
    assert result.mesh.is_watertight and result.mesh.euler_number == 0
    assert np.abs(t.implicit(result.vertices)).mean() < 0.3 * result.grid.spacing


@pytest.mark.parametrize("name", ["sphere-around", "ellipsoid-around"])
def test_points_scattered_by_half_a_voxel_let_the_quadric_follow_the_normals(name):
    """Six points moved by noise of half a voxel per axis. Held nearly exactly, they bent the
    quadric off the normals: the sphere by flash missed them by 1.69 degrees (median) and came
    out 0.36 voxel from the truth on average; the ellipsoid under lamps, 2.59, was refused.
    Refitted with the points weighed as noisy, each meets them within a quarter degree and is
    the start, and the sphere lies within 0.08 voxel."""
    from .helpers import points_moved

    synthetic = make_scene(name, seed=0)
    solver = ws.Reconstructor(points_moved(synthetic.scene(), 0.5), resolution=64,
                              device="cpu")
    report = solver.fit_report
    assert report.shape == "quadric"
    assert np.median(report.residual_deg[report.weights > 0]) < 0.3
    if name == "sphere-around":
        solver.run(20)
        result = solver.result()
        distance = np.abs(synthetic.surface.signed_distance(result.vertices))
        assert distance.mean() < 0.15 * result.grid.spacing


@pytest.mark.parametrize("noise", [1.0, 2.0])
def test_exact_points_keep_the_quadric_that_holds_them(noise):
    """With exact points and a pixel of noise on the highlights, the refit that weighs the
    points as noisy meets the normals about as well (0.23 degrees against 0.26 on the sphere),
    and the quadric that holds the points exactly stays the start: they fix its depth. With
    two pixels the refit, bent to the noise, left the points a voxel off, far enough for the
    points to look noisy (NOISY_POINT_RATIO), and the sphere came out 0.96 h from the truth;
    its rays' pixel misses are 0.88 times the held fit's, not NOISY_REFIT_GAIN's 0.8."""
    scene = make_scene("sphere-around", seed=0, noise=noise).scene()
    grid = Grid.from_bounds(*scene.bounds(), resolution=64)
    fit = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    assert fit.run(wp.zeros(grid.shape, dtype=float, device="cpu")).shape == "quadric"
    assert fit.quadric.distance(scene.points.reshape(-1, 3)).max() < 0.01 * grid.spacing


def test_a_closed_form_shape_holds_the_points_in_its_median_and_four_in_five_near():
    """The points' test of a closed-form start: their median distance within 2/64 of the
    domain's size and four in five within 3/64, so points scattered by their noise pass, and
    a shape that misses many by more does not, at any resolution."""
    from types import SimpleNamespace

    stub = SimpleNamespace(grid=SimpleNamespace(origin=np.zeros(3), upper=np.full(3, 0.64)))
    stub._holds_points = lambda distance: ImplicitStart._holds_points(stub, distance)
    pixels = np.full(20, np.inf)  # no move of a highlight meets its normal
    stub._pixel_miss = lambda shape, rays: pixels
    stub._allowance, stub._noisier = PIXEL_NOISE, False
    rays = np.ones(20, dtype=bool)
    residual = np.zeros(20)  # every normal met
    near = np.full(6, 0.019)  # within two voxels: 0.02 = 2 * 0.64 / 64
    noisy, one_far, two_far, half_out = (near.copy() for _ in range(4))
    noisy[:2] = 0.028  # two points nearly three voxels off
    one_far[0] = 0.05  # one of six five voxels off
    two_far[:2] = 0.05
    half_out[:3] = 0.0215

    def suffices(residual, distance):
        return ImplicitStart._start_met(stub, None, residual, rays, distance) is not None

    assert suffices(residual, near)
    assert suffices(residual, noisy)
    assert suffices(residual, one_far)
    assert not suffices(residual, two_far)
    assert not suffices(residual, half_out)
    assert not suffices(residual, np.full(6, 0.021))
    assert suffices(residual, np.zeros(0))
    # the normals still decide first: missed by 5 degrees, unless their highlights need
    # moves within the allowance: PIXEL_NOISE where the rays show little noise (a median
    # miss of 1 px: sigma 0.85)
    assert not suffices(np.full(20, 5.0), near)
    pixels[:] = 1.0
    pixels[:2] = PIXEL_NOISE - 0.5
    assert suffices(np.full(20, 5.0), near)
    assert not suffices(np.full(20, 5.0), two_far)
    pixels[:2] = PIXEL_NOISE + 0.5  # 2 of 20 neither met nor clearly false: 10%, more than 5%
    assert not suffices(np.full(20, 5.0), near)
    pixels[1] = PIXEL_NOISE
    assert suffices(np.full(20, 5.0), near)
    # NOISE_SPREAD times the noise the rays show (Rayleigh's median: 1.1774 sigma)
    pixels[:] = 2.4
    allowance = NOISE_SPREAD * 2.4 / np.sqrt(2.0 * np.log(2.0))
    assert PIXEL_NOISE + 1.0 < allowance < PIXEL_WIDEST - 0.5
    pixels[:2] = allowance - 0.2
    assert suffices(np.full(20, 5.0), near)
    pixels[:2] = allowance + 0.2
    assert not suffices(np.full(20, 5.0), near)
    # and never beyond PIXEL_WIDEST, however wide the misses
    pixels[:] = 4.0
    pixels[:2] = PIXEL_WIDEST - 0.2
    assert suffices(np.full(20, 5.0), near)
    pixels[:2] = PIXEL_WIDEST + 0.2
    assert not suffices(np.full(20, 5.0), near)
    # judged the first time, the allowance is PIXEL_MET whatever the noise
    stub._allowance = PIXEL_MET
    pixels[:] = 2.4
    pixels[:2] = PIXEL_MET + 0.5
    assert not suffices(np.full(20, 5.0), near)
    stub._allowance = PIXEL_NOISE
    # the rays kept for the flow are those within PIXEL_MET: beyond, they count for the shape
    pixels[:] = np.linspace(0.0, PIXEL_NOISE, 20)
    met = ImplicitStart._start_met(stub, None, np.full(20, 5.0), rays, near)
    assert np.array_equal(met, pixels <= PIXEL_MET) and 0 < met.sum() < 20


@pytest.mark.parametrize("name, options", [("point-light", {"seed": 0}),
                                           ("freeform", {"seed": 0, "highlights": 30})])
def test_the_reported_misses_are_those_of_the_final_fit(name, options):
    """The report's angles are measured on the final (fine) fit even when cross-validation,
    which fits the coarsest grid, ran last and rejected nothing: the kept rays' median miss
    is 0.2 and 0.9 degrees. Measured with the rays still in the coarse grid's voxels, it was
    19 and 22 degrees."""
    synthetic = make_scene(name, **options)
    solver = ws.Reconstructor(synthetic.scene(), resolution=32, device="cpu")
    report = solver.fit_report
    kept = np.ones(len(report.residual_deg), dtype=bool)
    kept[report.rejected] = False
    assert np.median(report.residual_deg[kept]) < 2.0


def _sparse_bottle():
    """The bottle (seed 1) seen by half its highlights (21 flash-lit rays), 3 of its points."""
    synthetic = make_scene("bottle", seed=1)
    data = synthetic.scene_dict
    rng = np.random.default_rng(78)
    keep = sorted(rng.choice(len(data["specularities"]), 21, replace=False))
    points = sorted(rng.choice(len(data["points"]), 3, replace=False))
    data = {**data, "specularities": [data["specularities"][i] for i in keep],
            "points": [data["points"][i] for i in points]}
    return synthetic, ws.Scene.from_dict(data), keep, points


def _bottle_run(solver, synthetic, keep, points):
    """20 iterations of ``solver``; its mesh and symmetric distance to the truth (voxels)
    over the hull of the used highlights' true hits (``keep``) and points (``points``)."""
    from warpspec.evaluate import evaluate, truth_region

    solver.run(20)
    result = solver.result()
    mesh = result.mesh.copy()
    mesh.merge_vertices()
    region = truth_region(synthetic.truth_points[keep], synthetic.points[points])
    h = float(result.grid.spacing)
    return mesh, evaluate(mesh, synthetic.truth_mesh(), spacing=h, region=region,
                          samples=20000).chamfer / h


def test_fits_that_meet_the_normals_within_noise_tie_and_keep_the_shaped_prior(monkeypatch):
    """The sparse bottle with only the refined axis tried, its profile without the flatness:
    the surface of revolution misses 2 of the normals by 4.5 and 6.4 degrees, too many to be
    the start by itself, so the grid fit is made about it and about the quadric. Both meet
    all 21 normals, with median misses of 0.58 and 0.40 degrees (noise either way): the
    revolution's is kept, 0.94 h from the truth at 64 cells (the quadric's, once taken by its
    smaller median, 1.34 h). (With the flatness that profile meets the normals and is the
    start; so it is when the misses in pixels are allowed, which this test turns off: the two
    are within 3 px of it, and it comes out 0.42 h off.)"""
    from warpspec import implicit, revolution

    monkeypatch.setattr(revolution, "FLATNESS", 0.0)
    monkeypatch.setattr(implicit, "PIXEL_MET", 0.0)
    monkeypatch.setattr(implicit, "PIXEL_NOISE", 0.0)
    fit = revolution.fit_revolution

    def refined_only(*args, refine=True, **kwargs):
        return fit(*args, refine=True, **kwargs) if refine else (None, None)

    monkeypatch.setattr(revolution, "fit_revolution", refined_only)
    synthetic, scene, keep, points = _sparse_bottle()
    solver = ws.Reconstructor(scene, resolution=64, device="cpu")
    assert (solver.fit_report.shape, solver.fit_report.prior) == ("grid", "revolution")
    _, chamfer = _bottle_run(solver, synthetic, keep, points)
    assert chamfer < 1.1


@pytest.mark.parametrize("sparse", [True, False])
def test_a_flash_bottle_takes_the_axis_whose_profile_meets_more_lines(sparse):
    """By flash the closed-form axis is tried besides the refined one, and the shape whose
    profile meets more lines within 3 degrees is kept. The sparse bottle: about the refined
    axis (the truth's) the profile misses 2 of 21 lines by 4.5 and 6.4 degrees; about the
    closed-form axis (0.6 degrees off) it meets 20 within 3, and it is the start, 0.38 h from
    the truth (the grid fit made instead: 0.94). The bottle, seed 302 (highlights in three
    bands of height): about both axes the profile meets 40 of 42 lines, and the refined one
    is kept, a tube, 0.23 h from the truth (about the closed-form axis, 1.75 degrees off:
    0.53)."""
    if sparse:
        synthetic, scene, keep, points = _sparse_bottle()
        limit = 0.5
    else:
        synthetic = make_scene("bottle", seed=302)
        scene, keep, points = synthetic.scene(), slice(None), slice(None)
        limit = 0.35
    solver = ws.Reconstructor(scene, resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    mesh, chamfer = _bottle_run(solver, synthetic, keep, points)
    assert mesh.euler_number == 0
    assert chamfer < limit


@pytest.mark.parametrize("seed", [3, 10])
def test_a_closed_blob_is_fitted_about_the_prior_that_explains_it(seed):
    """A blob seen all around: a surface of revolution through two of its bumps meets more
    of its normals than the quadric (a tube), but the grid fit about it stays open at its
    ends, 11-12 of 40 rays missing it (not watertight, Euler -4 and -3, 1.7 h off at 32
    cells). Fitted about both, the fit that explains more kept rays (crossed where it meets
    their normals within 15 degrees) is taken: the quadric's, watertight with Euler 2, every
    ray kept, 0.09 and 0.12 h off."""
    synthetic = make_scene("blob", seed=seed)
    solver = ws.Reconstructor(synthetic.scene(), resolution=32, device="cpu")
    assert solver.fit_report.prior == "quadric"
    assert len(solver.fit_report.rejected) == 0
    solver.run(20)
    result = solver.result()
    mesh = result.mesh.copy()
    mesh.merge_vertices()
    assert mesh.is_watertight and mesh.euler_number == 2
    err = np.abs(synthetic.surface.implicit(result.vertices)).mean() / result.grid.spacing
    assert err < 0.25


@pytest.mark.parametrize("anchors", [1, 37, 600])
def test_support_distance_is_the_nearest_anchor_whichever_way_it_is_found(anchors):
    from scipy.spatial import cKDTree

    from warpspec.verdict import support_distance

    rng = np.random.default_rng(anchors)
    a = rng.uniform(-3.0, 5.0, size=(anchors, 3))
    v = rng.uniform(-3.0, 5.0, size=(5000, 3))
    spacing = 0.037
    want, _ = cKDTree(a).query(v)
    got = support_distance(v, a, spacing)
    assert np.allclose(got, want / spacing, rtol=1e-9, atol=1e-6)


def _grid_start_error(scene, synthetic) -> tuple[ImplicitStart, float]:
    """The grid fit's start and its mean distance (voxels) from a height field's truth.

    Over the span of the points (the data's), the distance taken vertically (the surfaces
    this is used on slope gently).
    """
    grid = Grid.from_bounds(*scene.bounds(), resolution=64)
    fit = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    phi = wp.zeros(grid.shape, dtype=float, device="cpu")
    assert fit.run(phi).shape == "grid"
    v, _ = triangulate(phi.numpy(), grid)
    xy = scene.points.reshape(-1, 3)[:, :2]
    span = np.all((v[:, :2] >= xy.min(axis=0)) & (v[:, :2] <= xy.max(axis=0)), axis=1)
    return fit, float(np.abs(synthetic.surface.implicit(v[span])).mean() / grid.spacing)


def test_noisy_points_let_the_grid_fit_follow_the_normals(monkeypatch):
    """The point-lit dome, seed 3, its five points half a voxel off per axis: held at
    POINT_WEIGHT, fits made without each point passed a median of 1.18 voxels from it, at
    NOISY_GRID_POINT_WEIGHT 0.40, so the points are judged noisy, and the start lies 0.32
    voxel from the truth over the points' span, not 0.66 (end to end 0.62 -> 0.30 h)."""
    import warpspec.implicit as I

    synthetic = make_scene("point-light", seed=3, point_noise=0.5)
    fit, loose = _grid_start_error(synthetic.scene(), synthetic)
    assert np.all(fit.point_weights == I.NOISY_GRID_POINT_WEIGHT)
    monkeypatch.setattr(I, "NOISY_GRID_RATIO", 0.0)  # never judged noisy
    fit, held = _grid_start_error(synthetic.scene(), synthetic)
    assert np.all(fit.point_weights == I.POINT_WEIGHT)
    assert loose < 0.6 * held


def test_exact_points_keep_the_grid_fit_that_holds_them():
    """The free-form patch, seed 1, exact points: fits made without each point pass within a
    median of 0.07 voxel of it held, 0.54 at the noisy weight; the points stay held (at the
    noisy weight the patch came out 0.31 h from the truth end to end, not 0.14); the start
    lies 0.15 voxel from the truth."""
    import warpspec.implicit as I

    synthetic = make_scene("freeform", seed=1)
    fit, error = _grid_start_error(synthetic.scene(), synthetic)
    assert np.all(fit.point_weights == I.POINT_WEIGHT)
    assert error < 0.25


def test_a_shape_the_normals_leave_open_keeps_its_exact_points_held():
    """The clean point-lit dome, seed 500: fits made without each point pass a median of 0.46
    voxel from it held, 0.14 at the noisy weight, as noisy points would; but refitted at that
    weight the dome meets its normals no closer (0.135 -> 0.129 degrees, the median), so the
    points stay held (taken, the dome came out 0.20 h from the truth, not 0.11); the start
    lies 0.13 voxel from the truth."""
    import warpspec.implicit as I

    synthetic = make_scene("point-light", seed=500)
    fit, error = _grid_start_error(synthetic.scene(), synthetic)
    assert np.all(fit.point_weights == I.POINT_WEIGHT)
    assert error < 0.3
