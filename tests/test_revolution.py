"""The surface of revolution of the implicit start: its fit, its field and the bottle it gives."""

import warnings

import numpy as np
import pytest
import warp as wp

import warpspec as ws
from warpspec import revolution as R
from warpspec.grid import Grid
from warpspec.kernels import implicit as K
from warpspec.normal_lines import first_crossing
from warpspec.revolution import SurfaceOfRevolution, fit_revolution
from warpspec.synthetic import make_scene


def _fit(synthetic, voxel: float = 0.02):
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    lo, hi = scene.domain
    return fit_revolution(origins, dirs, scene.points, lo=lo, hi=hi, voxel=voxel)


def _run(synthetic, solver, iterations: int):
    """Run ``iterations`` of the flow; the result and its mean distance to the truth (voxels)."""
    solver.run(iterations)
    result = solver.result()
    err = np.abs(synthetic.surface.implicit(result.vertices)).mean() / result.grid.spacing
    return result, err


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("outliers", [0.0, 0.25])
def test_fit_finds_the_bottle_axis_and_its_radius_at_the_points(seed, outliers):
    synthetic = make_scene("bottle", seed=seed, outliers=outliers)
    surface, used = _fit(synthetic)
    truth = synthetic.surface
    assert surface is not None
    # the axis: parallel to the truth's, through it
    assert abs(abs(float(surface.axis @ truth.axis)) - 1.0) < 1e-6
    offset = truth.base - surface.base
    assert np.linalg.norm(offset - (offset @ truth.axis) * truth.axis) < 1e-3
    # every false highlight's ray passes far from the axis and is left out, every true one used
    assert used.tolist() == synthetic.inliers.tolist()
    # the points lie on it, and so do the true highlights (radius error in voxels of 0.02)
    pts = synthetic.scene().points
    assert np.abs(surface.value(pts)).max() < 0.1 * 0.02
    hl = synthetic.truth_points[synthetic.inliers]
    body = (hl - truth.base) @ truth.axis < 0.1  # the body's ring: a cylinder's highlights
    assert np.abs(surface.value(hl[body])).max() < 0.1 * 0.02
    assert np.abs(surface.value(hl)).mean() < 1.0 * 0.02


@pytest.mark.parametrize("name", ["freeform", "ellipsoid-around", "point-light"])
def test_no_surface_of_revolution_without_a_common_axis(name):
    """Lines that pass near no common axis (free-form normals, lamps off the cameras) fit none."""
    surface, used = _fit(make_scene(name))
    assert surface is None
    assert used.mean() < 0.5


def test_field_kernel_matches_the_first_order_distance(device):
    heights = np.linspace(-1.0, 1.0, 81)
    radii = 0.4 + 0.15 * np.tanh(4.0 * heights)
    axis = np.array([0.0, 0.6, 0.8])
    surface = SurfaceOfRevolution(np.array([0.05, -0.1, 0.0]), axis, heights, radii)
    origin, h, shape = np.array([-0.8, -1.1, -1.0]), 0.05, (33, 41, 40)
    out = wp.zeros(shape, dtype=float, device=device)
    wp.launch(K.revolution_field, dim=shape,
              inputs=[wp.vec3(*(origin - surface.base)), h, wp.vec3(*axis),
                      float(heights[0]), float(heights[1] - heights[0]),
                      wp.array(radii.astype(np.float32), dtype=float, device=device),
                      wp.array(surface.slopes().astype(np.float32), dtype=float,
                               device=device)],
              outputs=[out], device=device)
    idx = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), axis=-1)
    exact = surface.value((origin + h * idx).reshape(-1, 3)).reshape(shape)
    assert np.abs(out.numpy() - exact).max() < 1e-5
    assert (exact < 0).any() and (exact > 0).any()


def test_a_cylinder_profile_is_met_where_a_cylinder_is():
    heights = np.linspace(-1.0, 1.0, 41)
    cylinder = SurfaceOfRevolution(np.zeros(3), np.array([0.0, 0.0, 1.0]), heights,
                                   np.full(41, 0.5))
    origins = np.array([[2.0, 0.0, 0.2], [2.0, 0.3, -0.4], [2.0, 0.8, 0.0]])
    dirs = np.array([[-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    hits, inside = cylinder.intersect(origins, dirs, np.full(3, -1.0), np.full(3, 1.0),
                                      step=0.02)
    assert inside.tolist() == [True, True, False]
    np.testing.assert_allclose(hits[0], [0.5, 0.0, 0.2], atol=1e-6)
    np.testing.assert_allclose(hits[1], [0.4, 0.3, -0.4], atol=1e-6)
    np.testing.assert_allclose(cylinder.gradient(hits[:1]), [[1.0, 0.0, 0.0]], atol=1e-9)
    # the tracer alone, on a plane: the first crossing, not the last
    hits, inside = first_crossing(lambda x: x[:, 0] - 0.25, origins, dirs, np.full(3, -1.0),
                                  np.full(3, 1.0), step=0.02)
    assert inside.all() and np.allclose(hits[:, 0], 0.25)


@pytest.mark.parametrize(("name", "seed", "outliers", "bound"),
                         [("bottle", 0, 0.1, 0.5), ("bottle-lamps", 1, 0.0, 0.3)])
def test_the_bottle_starts_from_a_surface_of_revolution(name, seed, outliers, bound):
    """Default options, a coarse grid, by flash and under lamps: the start is the surface of
    revolution, the tube open at both ends (Euler number 0), the false highlights rejected,
    within ``bound`` voxels."""
    synthetic = make_scene(name, seed=seed, outliers=outliers)
    solver = ws.Reconstructor(synthetic.scene(), resolution=32, device="cpu")
    assert solver.fit_report.shape == "revolution"
    result, err = _run(synthetic, solver, 20)
    assert result.mesh.euler_number == 0
    if outliers:
        assert sorted(r["index"] for r in result.rejected) == \
            np.flatnonzero(synthetic.outlier_mask).tolist()
    assert err < bound


def test_a_refit_that_holds_the_rays_own_hits_worse_is_not_taken():
    """Bottle-lamps seed 43 with 0.5 px of noise: the surface of revolution meets 39 normals
    within 3 degrees and a true one (#0, low on the body) by 6.8. Refitted without it, the
    body bulged 1.7 voxels between the points and missed it by 25 degrees (0.51 h from the
    truth end to end), and the met rays' own hits (where their normal lines meet the axis)
    lay farther from it: 90th percentile 0.65 voxel from the shape, 1.34 from the refit. The
    refit is not taken (0.11 h; resolution 64, one iteration)."""
    synthetic = make_scene("bottle-lamps", seed=43, noise=0.5)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    assert solver.fit_report.residual_deg[0] < 10.0
    _, err = _run(synthetic, solver, 1)
    assert err < 0.25


def test_by_flash_the_shape_is_fitted_again_to_the_lines_it_met():
    """A quarter false bends a surface of revolution fitted to every flash-lit normal line:
    on bottle seed 31 it met 62% of the normals within 3 degrees, six true ones missed by
    4-8, two false ones by only 7.2 and 7.6, and the grid fit made instead came out 1.34 h
    from the truth. Refitted to the lines it meets within 10 degrees (a second round), it
    rejects exactly the false ones and is the start (resolution 64, one iteration)."""
    synthetic = make_scene("bottle", seed=31, outliers=0.25)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    assert sorted(solver.fit_report.rejected) == np.flatnonzero(synthetic.outlier_mask).tolist()
    true = solver.fit_report.residual_deg[synthetic.inliers]
    assert true.max() < 1.0  # 8.1 degrees from the one round's shape
    _, err = _run(synthetic, solver, 1)
    assert err < 0.5


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_under_lamps_false_highlights_cost_refits_not_the_shape(seed):
    """A quarter of false highlights leaves the first axis 8-15 degrees off; the refits from
    the normal lines through the hits on the shape fitted last, each from the rays that shape
    met, find it, and the shape taken is fitted again without the rays it rejects (resolution
    64; seeds 2 and 3 were lost, seed 4 came out 1.1 degrees off, 0.5 voxel)."""
    synthetic = make_scene("bottle-lamps", seed=seed, outliers=0.25)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    assert set(solver.fit_report.rejected) >= set(np.flatnonzero(synthetic.outlier_mask))
    _, err = _run(synthetic, solver, 1)
    assert err < 0.25


def _revolution_rejecting_the_false(*, seed: int, outliers: float) -> float:
    """Bottle-lamps' mean distance (voxels) from the truth after one iteration at 64 cells.

    Asserts that its start is a surface of revolution rejecting exactly the false highlights.
    """
    synthetic = make_scene("bottle-lamps", seed=seed, outliers=outliers)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    assert sorted(solver.fit_report.rejected) == np.flatnonzero(synthetic.outlier_mask).tolist()
    return _run(synthetic, solver, 1)[1]


def test_under_lamps_true_highlights_the_refit_meets_are_tried_back():
    """Seed 11, a tenth false: the first shape taken misses three true highlights by 11-14
    degrees, and the refit without them misses them by 4-5 degrees out of sample, which makes
    it ambiguous; fitted again with them, it meets them within a degree and rejects exactly the
    false ones (0.63 voxel from the truth end to end before, 0.10 clean)."""
    assert _revolution_rejecting_the_false(seed=11, outliers=0.1) < 0.25


def test_a_false_highlight_missed_by_a_few_degrees_is_told_apart_by_a_refit_without_it():
    """Seed 11, a quarter false: the first shape meets 71% of the 38 normals within 3 degrees
    and misses 9 of the 10 false ones by 27-75; two rays (one false at 5.7 degrees, one true
    at 5.8) lie between 3 and 10, 5.3% against the 5% allowed, and the refit without the 9
    is no better (the grid fit made instead came out 0.51 voxel from the truth). Fitted to
    the rays met within 3 degrees, it misses the false one by 15 and meets the true one: exactly
    the false highlights are rejected, and the shoulder the false one bent comes back. The
    fits' last bits differ between machines, and on some the refits ran out first, each
    meeting more normals than the one before (27 of 38 the last, a false one at 6.1 degrees
    and a true one at 5.5): the fit to the rays met within 3 degrees is made then too (the
    grid fit made instead, 0.44 h off end to end; now 0.025)."""
    assert _revolution_rejecting_the_false(seed=11, outliers=0.25) < 0.2


def test_true_highlights_the_refits_left_out_come_back_from_the_axis_they_found():
    """Seed 21, a quarter false: the fits to the rays the shape before met find the axis
    (0.1 degree and 0.02 voxel from the truth) but leave the neck's 7 true highlights out,
    missed by 22-25 degrees where false ones had bent the profile; no shape is taken, and the
    grid fit made instead came out 1.6 voxels from the truth. Every ray refitted from that
    axis meets every true normal within 3 degrees and every false one beyond 10."""
    assert _revolution_rejecting_the_false(seed=21, outliers=0.25) < 0.25


def test_under_lamps_the_rays_hits_hold_the_body_between_the_points():
    """Seed 21, 0.5 px of noise, fitted from the true axis: the refit as by flash holds radii
    only at the points, and between those at heights -0.35 and 0.18 slopes alone bent the
    body out 2.3 voxels on average (0.96 voxel from the truth end to end). The rays' hits,
    kept as weak radius data, hold it within 0.34 (the whole profile over the points' heights
    within 1.6 voxels, 3.5 before)."""
    synthetic = make_scene("bottle-lamps", seed=21, noise=0.5)
    scene = synthetic.scene()
    truth = synthetic.surface
    origins, dirs = scene.rays()
    lo, hi = scene.domain
    voxel = Grid.from_bounds(lo, hi, resolution=64).spacing
    surface = R.fit_revolution_lit(origins, dirs, scene.normals(synthetic.truth_points),
                                   scene.points, lo=lo, hi=hi, voxel=voxel,
                                   axis=(truth.base, truth.axis), tilted=False)
    heights = np.sort((scene.points - truth.base) @ truth.axis)

    def radius_error(a: float, b: float) -> np.ndarray:
        h = np.linspace(a, b, 41)
        on_axis = truth.base + np.outer(h, truth.axis)
        fitted = np.interp((on_axis - surface.base) @ surface.axis, surface.heights,
                           surface.radii)
        return np.abs(fitted - truth.radius(h)) / voxel

    assert radius_error(heights[2], heights[3]).mean() < 0.5
    assert radius_error(heights[0], heights[-1]).max() < 2.0


@pytest.mark.parametrize("seed", [0, 1])
def test_under_lamps_points_weighed_as_noisy_leave_the_profile_to_the_rays(seed):
    """Six points moved by noise of half a voxel per axis, exact highlights, fitted from the
    true axis. Held exactly (POINT_WEIGHT), the points pull the profile off the truth (0.32 and
    1.17 voxels on average at the true highlights); weighed as noisy (NOISY_POINT_WEIGHT), the
    rays' hits give every radius, within 0.01 voxel, and the points lie 0.4 voxel off."""
    from .helpers import points_moved

    synthetic = make_scene("bottle-lamps", seed=seed)
    scene = points_moved(synthetic.scene(), 0.5)
    truth = synthetic.surface
    origins, dirs = scene.rays()
    lo, hi = scene.domain
    voxel = Grid.from_bounds(lo, hi, resolution=64).spacing
    normals = scene.normals(synthetic.truth_points)
    error = {}
    for weight in (R.POINT_WEIGHT, R.NOISY_POINT_WEIGHT):
        surface = R.fit_revolution_lit(origins, dirs, normals, scene.points, lo=lo, hi=hi,
                                       voxel=voxel, axis=(truth.base, truth.axis),
                                       tilted=False, point_weight=weight)
        error[weight] = np.abs(surface.value(synthetic.truth_points)).mean() / voxel
    assert error[R.POINT_WEIGHT] > 0.2
    assert error[R.NOISY_POINT_WEIGHT] < 0.05


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_under_lamps_points_scattered_by_half_a_voxel_are_not_held_exactly(seed):
    """The whole start, points moved as above. Held exactly, they bent the profile: seed 0's
    shape missed the normals by a median of 0.55 degrees, seed 2's by 0.38 (0.18 voxel from
    the truth after one iteration), and seed 1's fits met only 67% of them within 3 degrees,
    so none was the start. Refitted with the points weighed as noisy, the surface of
    revolution is the start, meets the normals within 0.2 degree (0.13-0.15) and lies within
    0.05 voxel of the truth after one iteration (0.016-0.033)."""
    from .helpers import points_moved

    synthetic = make_scene("bottle-lamps", seed=seed)
    solver = ws.Reconstructor(points_moved(synthetic.scene(), 0.5), resolution=64,
                              device="cpu")
    report = solver.fit_report
    assert report.shape == "revolution"
    assert np.median(report.residual_deg[report.weights > 0]) < 0.2
    _, err = _run(synthetic, solver, 1)
    assert err < 0.05


@pytest.mark.parametrize("sigma", [0.5, 1.0])
def test_under_lamps_the_noisy_refit_searches_the_axis_again(sigma):
    """Bottle-lamps seed 2 with points drawn half a voxel and a voxel off per axis (four of
    its six 1.1-2.2 voxels off at a voxel): the axis found while the points were held is
    tilted by them, and the refit from that axis alone was 0.40 and 0.87 voxel from the
    truth after one iteration; searched again from the tilted starts, 0.041 and 0.049."""
    synthetic = make_scene("bottle-lamps", seed=2, point_noise=sigma)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    _, err = _run(synthetic, solver, 1)
    assert err < 0.1


def test_under_lamps_exact_points_keep_the_profile_that_holds_them():
    """Exact points, a pixel of noise on the highlights: the refit with the points weighed as
    noisy meets the normals no closer (a median of 0.61 degrees against 0.69), and the profile
    that holds the points exactly stays the start (within 0.0002 voxel of them; the refit
    holds them at 0.18, the median)."""
    from warpspec.implicit import ImplicitStart
    from warpspec.solver import initial_plane

    scene = make_scene("bottle-lamps", seed=0, noise=1.0).scene()
    grid = Grid.from_bounds(*scene.bounds(), resolution=64)
    fit = ImplicitStart(scene, grid, wp.get_device("cpu"), initial_plane(scene, grid))
    assert fit.run(wp.zeros(grid.shape, dtype=float, device="cpu")).shape == "revolution"
    assert np.abs(fit.revolution.value(scene.points)).max() < 0.05 * grid.spacing


@pytest.mark.parametrize("tilted", [True, False])
@pytest.mark.parametrize("seed", [0, 1])
def test_under_lamps_the_axis_is_the_one_that_makes_one_smooth_profile(seed, tilted):
    """A lamp per camera: rays are no normal lines; from a guess 4 degrees and a voxel off, the
    axis whose hits make one smooth profile is the truth's, and the true highlights lie on it
    (refined from the guess alone too, as the refit without the rejected rays is)."""
    synthetic = make_scene("bottle-lamps", seed=seed)
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    normals = scene.normals(synthetic.truth_points)
    truth = synthetic.surface
    voxel = 0.02
    u = np.cross(truth.axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    guess = (truth.base + voxel * u, truth.axis + np.tan(np.radians(4.0)) * u)
    guess = (guess[0], guess[1] / np.linalg.norm(guess[1]))
    lo, hi = scene.domain
    surface = R.fit_revolution_lit(origins, dirs, normals, scene.points, lo=lo, hi=hi,
                                   voxel=voxel, axis=guess, tilted=tilted)
    assert surface is not None
    assert np.degrees(np.arccos(min(1.0, abs(float(surface.axis @ truth.axis))))) < 0.05
    assert np.abs(surface.value(synthetic.truth_points)).mean() < 0.3 * voxel
    assert np.abs(surface.value(scene.points)).max() < 0.1 * voxel


def test_cameras_in_one_ring_above_see_a_tube_not_a_patch():
    """Walked round at one height above the bottle, the cameras lie in a half-space (the plane
    guess), yet they see it from every side: the surface of revolution is tried, and taken."""
    with pytest.raises(ws.SceneError, match="rings"):
        make_scene("bottle", rings=3)
    synthetic = make_scene("bottle", rings=1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=32, device="cpu")
    assert solver.fit_report.guess == "plane"
    assert solver.fit_report.shape == "revolution"
    result, err = _run(synthetic, solver, 20)
    assert result.mesh.euler_number == 0
    assert err < 0.5


def test_arc_length_weights_match_the_slope_to_second_order():
    """Each third difference's row is weighed by ``(1 + r'^2)^(-7/4)`` at its middle: exactly
    on a cone (constant slope), and to second order in the knot spacing on a curved profile."""
    heights = np.linspace(-1.0, 1.0, 21)
    for slope in (0.0, 0.5, 2.0):
        w = R._arc_length_weights(heights, 0.3 + slope * heights)
        np.testing.assert_allclose(w, (1.0 + slope**2) ** -1.75, rtol=1e-12)
    errors = []
    for count in (41, 81, 161):
        h = np.linspace(-1.0, 1.0, count)
        w = R._arc_length_weights(h, 0.4 + 0.15 * np.tanh(4.0 * h))
        middle = 0.5 * (h[1:-2] + h[2:-1])
        exact = (1.0 + (0.6 / np.cosh(4.0 * middle) ** 2) ** 2) ** -1.75
        errors.append(np.abs(w - exact).max())
    assert errors[0] / errors[1] > 3.5 and errors[1] / errors[2] > 3.5


def test_a_steep_shoulder_costs_no_more_than_a_gentle_one(monkeypatch):
    """Measured along the profile, the third-order energy lets the fit be as steep as the
    data: on the flash-lit bottles the profile between the shoulder's highlights and the neck
    lies closer to the truth than with the energy measured along the axis."""
    errors = {}
    for weighted in (True, False):
        if not weighted:
            monkeypatch.setattr(R, "_arc_length_weights", lambda heights, radii: None)
        total = 0.0
        for seed in (3, 4, 5):
            synthetic = make_scene("bottle", seed=seed)
            surface, _ = _fit(synthetic)
            samples = synthetic.surface.sample(4000, seed=0, extent=(0.2, 0.8))
            total += np.abs(surface.value(samples)).mean() / 0.02
        errors[weighted] = total / 3
    assert errors[True] < 0.95 * errors[False]  # 0.45 against 0.72 voxels


def test_the_shoulder_keeps_the_curvature_its_highlights_show():
    """A ring of flashes at one height lights a bottle's shoulder in a band a fraction of a
    voxel high; the spread of the slopes there is the profile's curvature, carried across the
    unseen steep middle of the shoulder. On knots a twentieth of a voxel apart the profile
    between the shoulder's highlights and the neck is 0.46-0.62 voxels from the truth (mean
    distance, seeds 0, 2, 4, 6); on knots half a voxel apart, one slope per cell, 0.75-0.93."""
    errors = []
    for seed in (0, 2, 4, 6):
        synthetic = make_scene("bottle", seed=seed)
        surface, _ = _fit(synthetic)
        samples = synthetic.surface.sample(4000, seed=0, extent=(0.2, 0.8))
        errors.append(np.abs(surface.value(samples)).mean() / 0.02)
    assert max(errors) < 0.7
    assert np.mean(errors) < 0.6


def _worst_off(surface, truth, heights: np.ndarray, voxel: float) -> float:
    """The profile's largest distance (voxels) from the truth's circles at ``heights``, each
    sampled at 12 angles."""
    circles = truth.at(np.linspace(0.0, 6.0, 12)[:, None], np.asarray(heights)[None, :])
    return float(np.abs(surface.value(circles.reshape(-1, 3))).max()) / voxel


def _pair_at_one_height(truth, apart: float) -> np.ndarray:
    """Two points of the bottle's body a thousandth apart along its axis, the second moved
    ``apart`` outward."""
    pair = np.stack([truth.at(0.3, -0.3), truth.at(2.0, -0.301)])
    radial = pair[1] - truth.base - (pair[1] - truth.base) @ truth.axis * truth.axis
    pair[1] += apart * radial / np.linalg.norm(radial)
    return pair


def _assert_body_unbent(surface, truth, pair: np.ndarray, voxel: float) -> None:
    """The profile within half a voxel of the truth over the body, the pair within a tenth."""
    assert surface is not None
    assert _worst_off(surface, truth, np.linspace(-0.42, 0.1, 27), voxel) < 0.5
    assert np.abs(surface.value(pair)).max() < 0.1 * voxel


@pytest.mark.parametrize(("name", "seed", "apart"), [
    ("bottle", 0, 0.03), ("bottle-lamps", 0, 0.1), ("bottle-lamps", 7, 0.1)])
def test_two_points_at_one_height_ask_no_slope(name, seed, apart):
    """Two points a thousandth apart along the axis whose radii differ by ``apart`` voxel (as
    an axis a tenth or a quarter of a degree off leaves them) must not bend the body: the
    profile stays within half a voxel of the truth over the body, and both points within a
    tenth of a voxel. By flash the points weigh little; under lamps they weigh 40 times more
    and their heights and radii are averaged, else the slope between them is carried on as a
    wave over the body (1.9-2.2 voxels off)."""
    synthetic = make_scene(name, seed=seed)
    truth = synthetic.surface
    voxel = 0.02
    pair = _pair_at_one_height(truth, apart * voxel)
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    lo, hi = scene.domain
    points = np.concatenate([scene.points, pair])
    if name == "bottle":
        surface, _ = fit_revolution(origins, dirs, points, lo=lo, hi=hi, voxel=voxel)
    else:
        surface = R.fit_revolution_lit(origins, dirs, scene.normals(synthetic.truth_points),
                                       points, lo=lo, hi=hi, voxel=voxel,
                                       axis=(truth.base, truth.axis), tilted=False)
    _assert_body_unbent(surface, truth, pair, voxel)


def test_point_rows_average_only_points_within_half_a_voxel_of_height():
    """A lone point keeps its height and radius; points on a straight profile within half a
    voxel of each other's height are averaged onto it exactly."""
    voxel = 0.1
    h = np.array([0.0, 0.03, 0.06, 1.0, 3.0])
    r = 0.5 + 2.0 * h  # a cone: straight
    r[3] += 0.3  # off the cone, alone in its window
    heights, radii, weights = R._point_rows(h, r, 7.0, voxel)
    np.testing.assert_allclose(radii[:3], 0.5 + 2.0 * heights[:3], atol=1e-12)
    np.testing.assert_allclose(heights[:3], [0.015, 0.03, 0.045], atol=1e-12)
    assert heights[3] == 1.0 and radii[3] == r[3]
    assert heights[4] == 3.0 and radii[4] == r[4]
    np.testing.assert_array_equal(weights, 7.0)


def test_the_flatness_draws_a_drop_held_at_both_ends_straight():
    """A cylinder's weights are FLATNESS between the lowest and highest held heights and none
    outside; a cone of slope FLAT_SLOPE has half. Radii held at both ends and nothing between:
    uniform weights make the straight profile the cheapest, each cell dropping the same."""
    heights = np.linspace(0.0, 1.0, 41)
    flat = R._flatness_weights(heights, np.ones(41), np.array([0.2, 0.8]))
    middle = 0.5 * (heights[1:] + heights[:-1])
    inside = (middle >= 0.2) & (middle <= 0.8)
    np.testing.assert_allclose(flat[inside], R.FLATNESS)
    assert np.all(flat[~inside] == 0.0)
    # a slope of FLAT_SLOPE halves the weight
    cone = R._flatness_weights(heights, R.FLAT_SLOPE * heights, np.array([0.0, 1.0]))
    np.testing.assert_allclose(cone, 0.5 * R.FLATNESS)
    values = (np.array([0.0, 1.0]), np.array([1.0, 2.0]), np.array([1e6, 1e6]))
    none = (np.zeros(0),) * 4
    radii, _ = R._solve_profile(heights, scale=1.0, smoothness=1e-12, values=values,
                                slopes=none, flat=np.full(40, R.FLATNESS))
    np.testing.assert_allclose(radii, 1.0 + heights, atol=1e-6)


def test_a_sharp_shoulder_drops_where_no_datum_holds_the_profile_flat(monkeypatch):
    """A bottle by flash with a shoulder half as wide as the catalogue's (seeds 0-2): the
    highlights see it in two bands, and the neck's point lies well above them. With the
    flatness the drop goes between the bands, the neck 0.34-0.46 voxel off at most; with the
    third-order energy alone it is spread up to the neck's point, the neck 3.4-3.7 voxels
    fat."""
    def neck_error() -> float:
        worst = []
        for seed in range(3):
            synthetic = make_scene("bottle", seed=seed, shoulder=0.55)
            scene, truth = synthetic.scene(), synthetic.surface
            grid = Grid.from_bounds(*scene.domain, resolution=64)
            surface, _ = fit_revolution(*scene.rays(), scene.points, lo=grid.origin,
                                        hi=grid.upper, voxel=grid.spacing)
            neck = np.linspace(truth.shoulder + 2.0 * truth.width, 0.8, 9)
            worst.append(_worst_off(surface, truth, neck, grid.spacing))
        return max(worst)

    assert neck_error() < 1.0
    monkeypatch.setattr(R, "FLATNESS", 0.0)
    assert neck_error() > 3.0


def test_the_bottle_takes_a_shoulder_width_in_range():
    with pytest.raises(ws.SceneError, match="shoulder"):
        make_scene("bottle", shoulder=0.1)
    with pytest.raises(ws.SceneError, match="shoulder"):
        make_scene("bottle-lamps", shoulder=True)
    sharp, plain = make_scene("bottle", shoulder=0.5), make_scene("bottle")
    assert sharp.surface.width == pytest.approx(0.5 * plain.surface.width)
    np.testing.assert_array_equal(sharp.surface.axis, plain.surface.axis)
    for bad in (0.4, 1.7, True, "1"):
        with pytest.raises(ws.SceneError, match="body"):
            make_scene("bottle", body=bad)
    fat = make_scene("bottle-lamps", body=1.3)
    assert fat.surface.body == pytest.approx(1.3 * make_scene("bottle-lamps").surface.body)
    # the domain holds the wider body with its margin
    assert np.ptp(np.asarray(fat.domain)[:, 0]) > 1.25 * np.ptp(np.asarray(plain.domain)[:, 0])
    np.testing.assert_array_equal(make_scene("bottle", body=1.0).points, plain.points)


def _started_and_plain(synthetic, monkeypatch):
    """The profile fitted by flash as it is, and from the cylinder alone (no other start
    tried), with the voxel of the grid at 64."""
    voxel = Grid.from_bounds(*synthetic.domain, resolution=64).spacing
    started = _fit(synthetic, voxel)[0]
    monkeypatch.setattr(R, "_shoulder_starts", lambda *args: [])
    return started, _fit(synthetic, voxel)[0], voxel


def test_a_fat_bottle_with_a_sharp_shoulder_starts_where_it_shows_no_unseen_highlight(
        monkeypatch):
    """A body of radius about 0.45 and a shoulder half as wide (seed 0): from the cylinder the
    profile left the shoulder's top highlights far out and the neck fat, the truth 2.2 voxels
    from it on average; fitted again where that profile showed its cameras highlights they
    did not see, 0.07."""
    synthetic = make_scene("bottle", seed=0, shoulder=0.5, body=1.3)
    started, plain, voxel = _started_and_plain(synthetic, monkeypatch)
    assert _truth_distance(synthetic, started, voxel) < 0.3
    assert _truth_distance(synthetic, plain, voxel) > 1.0


def test_beyond_its_data_the_profile_keeps_its_radius():
    """Without the point on the neck the profile's last datum is the neck's highlights, where
    the shoulder still slopes: the neck above keeps the radius found there (2.6-2.9 voxels
    off at most, seeds 0-3) instead of thinning on along that slope (3.2-4.4)."""
    heights = np.linspace(0.0, 1.0, 11)
    flat = R._flat_ends(heights, np.linspace(1.0, 2.0, 11), np.array([0.25, 0.61]))
    # the knots of the cells that hold 0.25 (0.2, 0.3) and 0.61 (0.6, 0.7) keep their radii
    np.testing.assert_allclose(flat, [1.2] * 3 + [1.3, 1.4, 1.5, 1.6, 1.7] + [1.7] * 3)
    whole = R._flat_ends(heights, np.linspace(1.0, 2.0, 11), np.array([0.0, 1.0]))
    np.testing.assert_allclose(whole, np.linspace(1.0, 2.0, 11))
    worst = []
    for seed in range(4):
        synthetic = make_scene("bottle", seed=seed)
        scene, truth = synthetic.scene(), synthetic.surface
        pts = scene.points[(scene.points - truth.base) @ truth.axis < 0.5]
        origins, dirs = scene.rays()
        lo, hi = scene.domain
        surface, _ = fit_revolution(origins, dirs, pts, lo=lo, hi=hi, voxel=0.02)
        worst.append(_worst_off(surface, truth, np.linspace(0.6, 0.84, 13), 0.02))
    assert np.mean(worst) < 3.2


def test_the_rays_are_traced_to_the_profile_as_it_is_kept_beyond_its_data():
    """The bottle by flash, seed 302 (highlights in three bands of height, no point on the
    neck), about the refined axis (the truth's): traced to the raw profile, whose third-order
    energy swelled it beyond its data past the cameras standing there, 28 of the 42 rays
    started inside it every third round, met it where they left it, and asked the wrong
    slopes; the profile never settled and missed the neck's 14 lines by 22-25 degrees (1.05 h
    from the truth). Traced to the profile held flat beyond its data, as it is returned, it
    meets 40 within 3 degrees."""
    from warpspec.geometry import miss_deg

    synthetic = make_scene("bottle", seed=302)
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    lo, hi = scene.domain
    voxel = Grid.from_bounds(lo, hi, resolution=64).spacing
    surface, used = fit_revolution(origins, dirs, scene.points, lo=lo, hi=hi, voxel=voxel)
    assert used.all()
    hits, inside = surface.intersect(origins, dirs, lo, hi, step=voxel)
    miss = miss_deg(surface.gradient(hits), -dirs, inside)
    assert inside.all() and np.mean(miss <= 3.0) > 0.9
    truth = synthetic.truth_mesh().vertices
    assert np.abs(surface.value(truth)).mean() / voxel < 0.4


@pytest.mark.parametrize("kind", ["torus", "revolution"])
def test_the_grid_fit_prior_is_the_shape_in_the_level_voxels(kind):
    """A torus or a surface of revolution as the grid fit's prior: its field on a coarser
    level's grid, in that level's voxels, is its distance divided by the level's spacing."""
    from warpspec.grid import Grid
    from warpspec.implicit import ImplicitStart
    from warpspec.torus import Torus

    synthetic = make_scene("torus" if kind == "torus" else "bottle")
    scene = synthetic.scene()
    lo, hi = scene.domain
    start = ImplicitStart(scene, Grid.from_bounds(lo, hi, resolution=64), "cpu", None)
    s = synthetic.surface
    if kind == "torus":
        start.prior = Torus(np.asarray(s.centre, float), np.asarray(s.axis, float),
                            float(s.major), float(s.minor))
    else:
        heights = np.linspace(-0.6, 1.0, 161)
        start.prior = SurfaceOfRevolution(np.asarray(s.base, float), np.asarray(s.axis, float),
                                          heights, np.array([s.radius(h) for h in heights]))
    level = Grid.from_bounds(lo, hi, resolution=16)
    out = wp.zeros(level.shape, dtype=float, device="cpu")
    start._prior_field(level, out, unit=level.spacing)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in level.shape], indexing="ij"), axis=-1)
    exact = start.prior.value(level.origin + level.spacing * idx.reshape(-1, 3))
    assert np.abs(out.numpy().ravel() - exact / level.spacing).max() < 1e-4
    assert (exact < 0).any() and (exact > 0).any()


def test_a_shape_that_misses_a_few_normals_is_the_grid_fit_prior(monkeypatch):
    """Lamps, the cameras on one ring above the bottle (seed 0), its profile refitted without
    the rays' hits as radius data and without the flatness: the surface of revolution found
    has the axis and the points, but misses 3 of the 36 normals by 3.2-3.4 degrees (the
    shoulder's top), so it is no start by itself. The grid fit then smooths about it, not
    about the quadric: 0.5 voxel off (about the quadric, a sphere-like blob 5 voxels off).
    With the hits held the shape is the start, 0.02 voxel off; with the flatness (the
    default) it is too; and so it is when its misses are judged a second time with 5 px of
    noise on the highlights (``PIXEL_NOISE``), which this test turns off."""
    from warpspec import implicit

    monkeypatch.setattr(R, "LIT_HIT_WEIGHT", 0.0)
    monkeypatch.setattr(R, "FLATNESS", 0.0)
    monkeypatch.setattr(implicit, "PIXEL_NOISE", implicit.PIXEL_MET)
    synthetic = make_scene("bottle-lamps", rings=1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "grid"
    assert solver.fit_report.prior == "revolution"
    _, err = _run(synthetic, solver, 1)
    assert err < 0.75


def test_under_lamps_seen_from_one_ring_the_shape_held_by_the_hits_is_the_start():
    """The scene above with the rays' hits held: the surface of revolution is the start, 0.02
    voxel from the truth (the grid fit made about the shape without them came out 0.41)."""
    synthetic = make_scene("bottle-lamps", rings=1)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    _, err = _run(synthetic, solver, 1)
    assert err < 0.1


def test_at_two_pixels_the_surface_of_revolution_that_met_most_is_judged_by_the_noise():
    """The bottle under lamps at 2 px, seed 4: with 5 px no surface of revolution is the start
    (the refit that meets 95% of the normals within 3 degrees leaves 2 of its 37 rays 3-10
    degrees off and beyond 5 px), and the grid fit in its place came out 0.53 h off. Judged
    again with the noise its rays show, that refit is the start, 0.30 voxel from the truth
    after one iteration (0.29 h end to end); widened for each fit as it came, the crude first
    one was taken (84% within 3 degrees; 1.01 h)."""
    synthetic = make_scene("bottle-lamps", seed=4, noise=2.0)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape == "revolution"
    _, err = _run(synthetic, solver, 1)
    assert err < 0.45


def test_only_a_shape_that_holds_the_points_can_be_the_prior():
    """A torus moved a fifth along its axis (3.8 voxels at resolution 64) misses the points
    (their median 2.6 voxels off): it is neither the start nor the grid fit's prior; the true
    torus is both. Moved a tenth, their median is 1.45 voxels off, within the noise that
    points from structure from motion may carry, and only the normals refuse it."""
    from warpspec.grid import Grid
    from warpspec.implicit import ImplicitStart
    from warpspec.torus import Torus

    synthetic = make_scene("torus")
    scene = synthetic.scene()
    lo, hi = scene.domain
    start = ImplicitStart(scene, Grid.from_bounds(lo, hi, resolution=32), "cpu", None)
    s = synthetic.surface
    axis = np.asarray(s.axis, float)
    moved = Torus(np.asarray(s.centre, float) + 0.2 * axis, axis, float(s.major),
                  float(s.minor))
    assert start._accept(moved) is None and start._best is None
    truth = Torus(np.asarray(s.centre, float), axis, float(s.major), float(s.minor))
    assert start._accept(truth) is truth
    assert start._best[1] is truth and start._best[0] > 0.9


def test_the_cameras_ring_gives_an_axis_when_the_quadric_does_not():
    """Camera centres on a tilted ring (a little jitter): its axis; on a line, or fewer than
    three: none. Under lamps from one ring above with a quarter false (seed 0), the quadric's
    hits give an axis 45 degrees off; from the ring the bottle is found (was a fat blob 5.6
    voxels off, which the verdict refuses)."""
    from warpspec.implicit import camera_ring

    rng = np.random.default_rng(0)
    axis = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    u = np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    t = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    centre = np.array([0.3, 0.1, 0.7])
    ring = centre + 1.6 * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * w)
    ring = ring + 0.01 * rng.standard_normal(ring.shape)
    c, a = camera_ring(np.repeat(ring, 2, axis=0))  # two highlights per camera
    assert abs(abs(float(a @ axis)) - 1.0) < 1e-3
    assert np.linalg.norm(np.cross(c - centre, axis)) < 0.02
    assert camera_ring(np.outer(np.arange(5.0), axis)) is None
    assert camera_ring(ring[:2]) is None
    synthetic = make_scene("bottle-lamps", rings=1, outliers=0.25)
    solver = ws.Reconstructor(synthetic.scene(), resolution=64, device="cpu")
    assert solver.fit_report.shape in ("revolution", "grid")
    result, err = _run(synthetic, solver, 1)
    assert err < 0.75 and result.verdict.supported


def test_a_shape_no_surface_of_revolution_fits_warns_nothing():
    """The blob under a quarter false highlights (seed 0): the surfaces of revolution tried
    for it have profiles whose slopes overflow and systems that turn singular. They are no
    answer (the grid fit follows), and no numerical warning reaches the user (64 did)."""
    synthetic = make_scene("blob", outliers=0.25)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver = ws.Reconstructor(synthetic.scene(), resolution=32, device="cpu")
    assert solver.fit_report.shape == "grid"


def test_leaving_a_slope_out_matches_the_profile_fitted_without_it():
    """The out-of-sample misses come from one factorisation (Sherman-Morrison); each must be
    the angle to the profile refitted from scratch without that line."""
    rng = np.random.default_rng(4)
    heights = np.linspace(-1.0, 1.0, 201)
    values = (np.array([-0.8, -0.1, 0.5, 0.9]), np.array([0.5, 0.45, 0.3, 0.3]),
              np.full(4, 20.0))
    sh = rng.uniform(-0.95, 0.95, 12)
    angle = rng.uniform(-0.6, 0.6, 12)
    across = rng.uniform(0.0, 0.2, 12)  # a component across the meridian plane
    snh, snr = np.sin(angle) * np.sqrt(1 - across**2), np.cos(angle) * np.sqrt(1 - across**2)
    sw = rng.uniform(0.5, 1.0, 12)
    options = {"scale": 2.0, "smoothness": 1e-6, "values": values}
    radii, misses = R._solve_profile(heights, slopes=(sh, snh, snr, sw), leave_out=True,
                                     **options)
    step = heights[1] - heights[0]
    for i in range(12):
        keep = np.arange(12) != i
        without, _ = R._solve_profile(
            heights, slopes=(sh[keep], snh[keep], snr[keep], sw[keep]), **options)
        j = int((sh[i] - heights[0]) // step)
        slope = (without[j + 1] - without[j]) / step
        expected = np.degrees(np.arccos(abs(snr[i] - snh[i] * slope) / np.hypot(1.0, slope)))
        assert misses[i] == pytest.approx(expected, abs=1e-6)
    # a slope fitted with the line meets it closer than the one made without it
    assert np.all(misses > 0.0)


def test_the_profile_is_the_least_squares_solution_of_its_rows():
    """The banded normal equations must give the minimiser of the stacked rows (radius data,
    slope data, weighted third differences), as a dense least-squares solve finds it."""
    rng = np.random.default_rng(7)
    heights = np.linspace(-1.0, 1.0, 41)
    step, count = heights[1] - heights[0], len(heights)
    vh, vr, vw = rng.uniform(-1.0, 1.0, 6), rng.uniform(0.2, 0.6, 6), rng.uniform(1.0, 20.0, 6)
    sh, snh = rng.uniform(-1.0, 1.0, 9), rng.uniform(-0.5, 0.5, 9)
    snr, sw = np.sqrt(1.0 - snh**2), rng.uniform(0.5, 1.0, 9)
    bend = rng.uniform(0.5, 2.0, count - 3)
    smoothness, scale = 1e-4, 2.0
    radii, residuals = R._solve_profile(heights, scale=scale, smoothness=smoothness,
                                        values=(vh, vr, vw), slopes=(sh, snh, snr, sw),
                                        bend=bend)
    rows, target = [], []
    for h, r, w in zip(vh, vr, vw, strict=True):
        i = min(int((h - heights[0]) // step), count - 2)
        t = (h - heights[i]) / step
        row = np.zeros(count)
        row[i], row[i + 1] = w * (1.0 - t), w * t
        rows.append(row)
        target.append(w * r)
    for h, nh, nr, w in zip(sh, snh, snr, sw, strict=True):
        j = min(int((h - heights[0]) // step), count - 2)
        row = np.zeros(count)
        row[j], row[j + 1] = -w * nr / step, w * nr / step
        rows.append(row)
        target.append(-w * nh)
    k = step / scale
    weight = np.sqrt(smoothness * k) / k**3 / scale * bend
    for r in range(count - 3):
        row = np.zeros(count)
        row[r: r + 4] = weight[r] * np.array([-1.0, 3.0, -3.0, 1.0])
        rows.append(row)
        target.append(0.0)
    A, b = np.array(rows), np.array(target)
    expected = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.max(np.abs(radii - expected)) < 1e-8 * np.max(np.abs(expected))
    data = len(vh) + len(sh)
    assert np.allclose(residuals, A[:data] @ expected - b[:data], atol=1e-8)


def test_a_false_line_that_passes_near_the_axis_is_left_out():
    """Bottle seed 11, a quarter false: one false highlight's line passes near the axis and
    asks a slope 50 degrees off between the shoulder's band of highlights and the neck's. The
    profile followed it, 1.1 voxels from the truth on average and 6.6 at most; left out by its
    out-of-sample miss, 0.25 on average."""
    synthetic = make_scene("bottle", seed=11, outliers=0.25)
    surface, used = _fit(synthetic)
    assert used.tolist() == synthetic.inliers.tolist()
    lo, hi = synthetic.scene().domain
    v = np.asarray(synthetic.truth_mesh().vertices)
    v = v[np.all((v >= lo) & (v <= hi), axis=1)]
    err = np.abs(surface.value(v)) / 0.02
    assert err.mean() < 0.3 and err.max() < 1.3


def test_a_singular_profile_system_gives_no_shape_and_no_error():
    """A profile's normal equations that are exactly singular give NaN radii and misses
    (not defined), without a warning. The lines of a blob seen all around (seed 9) make
    them positive definite but not in floating point (the Cholesky factorisation fails):
    the fit solves them by LU, without a warning, and its shape, if any, is finite."""
    heights = np.linspace(-1.0, 1.0, 51)
    empty = (np.zeros(0), np.zeros(0), np.zeros(0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # singular: NaN, without a warning
        radii, misses = R._solve_profile(
            heights, scale=2.0, smoothness=0.0, values=empty,
            slopes=(np.array([0.1]), np.array([0.0]), np.array([1.0]), np.array([1.0])),
            leave_out=True)
    assert misses.shape == (1,) and np.isnan(misses).all() and np.isnan(radii).all()
    scene = make_scene("blob", seed=9).scene()
    grid = Grid.from_bounds(*scene.domain, resolution=64)  # the implicit start's grid
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        surface, _ = fit_revolution(*scene.rays(), scene.points, lo=grid.origin,
                                    hi=grid.upper, voxel=grid.spacing)
    assert surface is None or np.all(np.isfinite(surface.radii))


def test_a_profile_the_cholesky_factorisation_refuses_is_solved_by_lu(monkeypatch):
    """Where floating point leaves the banded normal equations not positive definite, the
    banded LU factorisation gives the radii and the out-of-sample misses that a dense
    least-squares solve gives (forced here by refusing every Cholesky factorisation)."""
    import scipy.linalg

    heights = np.linspace(-1.0, 1.0, 81)
    rng = np.random.default_rng(4)
    vh = rng.uniform(-0.9, 0.9, 6)
    values = (vh, 0.5 + 0.1 * vh**2, np.ones(6))
    sh = rng.uniform(-0.9, 0.9, 12)
    slopes = (sh, rng.normal(0.0, 0.1, 12), np.ones(12), np.ones(12))
    kwargs = dict(scale=2.0, smoothness=1e-3, values=values, slopes=slopes, leave_out=True)
    radii, misses = R._solve_profile(heights, **kwargs)

    def refuse(*args, **kw):
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(scipy.linalg, "cholesky_banded", refuse)
    lu_radii, lu_misses = R._solve_profile(heights, **kwargs)
    assert np.all(np.isfinite(lu_radii))
    assert np.allclose(lu_radii, radii, rtol=1e-8, atol=1e-10)
    assert np.allclose(lu_misses, misses, rtol=1e-6, atol=1e-8)


def test_the_lines_returned_are_those_the_profile_was_fitted_to(monkeypatch):
    """With no pass left to refit, a line the check would leave out stays in the fit, and the
    mask returned says so (it said left out while the profile still followed it)."""
    monkeypatch.setattr(R, "LEAVE_OUT_PASSES", 0)
    synthetic = make_scene("bottle", seed=11, outliers=0.25)
    surface, used = _fit(synthetic)
    assert used.sum() == synthetic.inliers.sum() + 1  # the false line near the axis
    lo, hi = synthetic.scene().domain
    v = np.asarray(synthetic.truth_mesh().vertices)
    v = v[np.all((v >= lo) & (v <= hi), axis=1)]
    assert np.abs(surface.value(v)).mean() / 0.02 > 0.8  # it follows that line


def _truth_distance(synthetic, surface, voxel: float, origin=0.0) -> float:
    """Mean distance of the truth mesh's vertices from ``surface`` (voxels), the surface
    measured from ``origin``."""
    vertices = np.asarray(synthetic.truth_mesh().vertices) - origin
    return float(np.abs(surface.value(vertices)).mean()) / voxel


@pytest.mark.parametrize("seed", [1, 2, 4])
def test_by_flash_points_that_disagree_are_weighed_as_noisy(seed, monkeypatch):
    """Points moved by half a voxel per axis: held, the profile followed each one (0.45-0.94
    voxel from the truth); the profile fitted without each point misses it by a median of
    0.46-0.73 voxel, and refitted with the points as noisy it is 0.12-0.42 voxel off."""
    synthetic = make_scene("bottle", seed=seed, point_noise=0.5)
    lo, hi = synthetic.domain
    voxel = Grid.from_bounds(lo, hi, resolution=64).spacing
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    noisy = fit_revolution(origins, dirs, scene.points, lo=lo, hi=hi, voxel=voxel)[0]
    monkeypatch.setattr(R, "NOISY_PROFILE_SIZE", np.inf)
    held = fit_revolution(origins, dirs, scene.points, lo=lo, hi=hi, voxel=voxel)[0]
    assert _truth_distance(synthetic, noisy, voxel) < 0.45
    assert _truth_distance(synthetic, held, voxel) > _truth_distance(synthetic, noisy, voxel) + 0.1
    # the points are left a fraction of a voxel off, not held
    assert np.median(np.abs(noisy.value(scene.points))) > 0.1 * voxel


@pytest.mark.parametrize(("seed", "noise"), [(0, 0.0), (3, 0.0), (8, 1.0)])
def test_by_flash_exact_points_still_hold_the_profile(seed, noise):
    """Exact points, clean or with a pixel of noise on the highlights: the profile without
    each point still passes it (medians 0.01-0.23 voxel), and the profile holds them."""
    synthetic = make_scene("bottle", seed=seed, noise=noise)
    lo, hi = synthetic.domain
    voxel = Grid.from_bounds(lo, hi, resolution=64).spacing
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    surface = fit_revolution(origins, dirs, scene.points, lo=lo, hi=hi, voxel=voxel)[0]
    assert np.abs(surface.value(scene.points)).max() < 0.1 * voxel


def test_points_at_one_height_are_judged_each_on_its_own():
    """Two points within half a voxel of height share one averaged radius row in the fit
    (:func:`_point_rows`); judged so, each left out kept its twin's row at their mean and was
    met within 0.01 voxel however far apart their radii (bottle seeds 3 and 10, points a voxel
    off: medians 0.01, the points held, 0.79 and 1.03 voxel from the truth). Judged each on its
    own row, the medians are 0.65 and 1.82 and the points are weighed as noisy."""
    synthetic = make_scene("bottle", seed=3, point_noise=1.0)
    grid = Grid.from_bounds(*synthetic.domain, resolution=64)
    scene = synthetic.scene()
    origins, dirs = scene.rays()
    surface = fit_revolution(origins, dirs, scene.points, lo=grid.origin, hi=grid.upper,
                             voxel=grid.spacing)[0]
    heights = np.sort(surface.split(scene.points)[0]) / grid.spacing
    assert np.min(np.diff(heights)) < 0.5  # a pair within half a voxel of height
    assert _truth_distance(synthetic, surface, grid.spacing) < 0.5


def test_the_points_disagree_by_their_median_miss():
    scale = 64.0  # a voxel of the domain at resolution 64 is 1
    assert R._points_disagree(np.array([0.5, 0.4, 0.01, 0.6]), scale)
    assert not R._points_disagree(np.array([0.1, 0.2, 0.05, 0.6]), scale)
    # NaN misses (a point no other datum predicts) are no verdict, nor are fewer than three
    assert R._points_disagree(np.array([0.5, np.nan, 0.4, 0.6]), scale)
    assert not R._points_disagree(np.array([0.5, np.nan, np.nan, 0.6]), scale)


def test_the_points_judged_alike_about_any_origin():
    """The solver's frame (the grid's centre) and the world's give one profile, the points
    judged noisy in both (bottle seed 2, points a voxel off: 0.87 voxel from the truth)."""
    synthetic = make_scene("bottle", seed=2, point_noise=1.0)
    grid = Grid.from_bounds(*synthetic.domain, resolution=64)
    centre = grid.origin + 0.5 * grid.spacing * (np.asarray(grid.shape) - 1)
    distances = []
    for origin in (np.zeros(3), centre):
        scene = synthetic.scene().translated(origin)
        origins, dirs = scene.rays()
        surface = fit_revolution(origins, dirs, scene.points, lo=grid.origin - origin,
                                 hi=grid.upper - origin, voxel=grid.spacing)[0]
        distances.append(_truth_distance(synthetic, surface, grid.spacing, origin))
    assert abs(distances[0] - distances[1]) < 0.01
    assert max(distances) < 1.0


def _flash_ring(surface, heights: np.ndarray, spots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cameras 1.6 from the z axis at ``heights``, on azimuths around it, each with one line
    aimed at the height ``spots`` of the ``surface`` (a profile about z) on its meridian."""
    az = np.linspace(0.0, 2.0 * np.pi, len(heights), endpoint=False)
    radial = np.c_[np.cos(az), np.sin(az), np.zeros(len(az))]
    cameras = 1.6 * radial + np.c_[0 * az, 0 * az, heights]
    radii = np.interp(spots, surface.heights, surface.radii)
    aim = radii[:, None] * radial + np.c_[0 * az, 0 * az, spots]
    dirs = aim - cameras
    return cameras, dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def test_unseen_highlights_are_those_a_profile_shows_its_flash_cameras_that_no_line_saw():
    """A cone ``r = 0.3 - 0.2 h`` about z, flash cameras 1.6 from the axis at heights ``h_c``:
    each sees its highlight where the normal points at it, at ``h = (h_c - 0.26) / 1.04``;
    a cylinder of radius 0.3 shows it at ``h_c`` instead, 0.25 away."""
    voxel = 0.02
    heights = np.arange(-1.0, 1.0 + 1e-9, voxel / 20.0)
    axis = np.array([0.0, 0.0, 1.0])
    cone = SurfaceOfRevolution(np.zeros(3), axis, heights, 0.3 - 0.2 * heights)
    cylinder = SurfaceOfRevolution(np.zeros(3), axis, heights, np.full(len(heights), 0.3))
    lo, hi = np.full(3, -0.5), np.full(3, 0.5)
    hc = np.array([-0.1, 0.0, 0.1, 0.2, 0.3, 0.4, 0.45])
    spots = (hc - 0.26) / 1.04
    cameras, dirs = _flash_ring(cone, hc, spots)

    def unseen(surface, d=dirs):
        return R._unseen_highlights(surface, cameras, d, lo=lo, hi=hi, voxel=voxel)

    assert unseen(cone) == 0
    # the cylinder's highlights lie at h_c, where no line passes
    assert unseen(cylinder) == len(hc)
    # one line aimed 5 voxels above its highlight misses it; 2 voxels above still sees it
    for off, count in ((5.0, 1), (2.0, 0)):
        moved = dirs.copy()
        up = spots[2] + off * voxel
        radial = np.r_[cameras[2, :2] / np.linalg.norm(cameras[2, :2]), 0.0]
        aim = (0.3 - 0.2 * up) * radial + up * axis - cameras[2]
        moved[2] = aim / np.linalg.norm(aim)
        assert unseen(cone, moved) == count
    # a highlight outside the domain is not asked for
    assert R._unseen_highlights(cylinder, cameras, dirs, lo=lo, hi=np.array([0.5, 0.5, 0.35]),
                                voxel=voxel) == len(hc) - 2


def test_a_profile_by_flash_starts_where_it_shows_no_highlight_its_cameras_missed(monkeypatch):
    """A bottle with a shoulder half as wide as the catalogue's (seed 3): from the cylinder
    the profile put the drop to the neck above the shoulder's top band of highlights, the
    neck up to 4.7 voxels fat (the truth 0.61 voxel from it on average), and showed the
    cameras above 25 highlights they did not see; started from drops between the points,
    none, and 0.06 voxel."""
    synthetic = make_scene("bottle", seed=3, shoulder=0.5)
    started, plain, voxel = _started_and_plain(synthetic, monkeypatch)
    lo, hi = synthetic.domain

    def unseen(surface):
        return R._unseen_highlights(surface, *synthetic.scene().rays(), lo=lo, hi=hi,
                                    voxel=voxel)

    assert unseen(started) == 0
    assert unseen(plain) > 5
    assert _truth_distance(synthetic, started, voxel) < 0.3
    assert (_truth_distance(synthetic, plain, voxel)
            > _truth_distance(synthetic, started, voxel) + 0.3)
