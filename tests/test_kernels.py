"""Kernel-level tests, each against an analytic answer."""

import numpy as np
import pytest
import warp as wp

from warpspec._parallel import SPLIT_MIN
from warpspec.geometry import plane_frame
from warpspec.grid import Grid
from warpspec.initial import HeightFit, monomials
from warpspec.kernels.band import launch_build_band
from warpspec.kernels.constraints import launch_claim_normals, launch_gaussian
from warpspec.kernels.flow import (
    NEIGHBOUR_OWNED,
    NO_OWNER,
    launch_flow_step,
    launch_flow_step_band,
)
from warpspec.kernels.rays import launch_intersect
from warpspec.kernels.start_fields import launch_bend, launch_height_field, launch_plane
from warpspec.kernels.stencils import (
    launch_central_gradient,
    launch_curvature_term,
    launch_upwind_gradient_norm,
)

from .helpers import cube_grid, interior, sphere_sdf


def to_device(a, device, dtype=float):
    return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=dtype, device=device)


def origin_of(grid):
    return tuple(float(v) for v in grid.origin)


def test_central_gradient_is_exact_for_a_linear_field(device):
    grid = cube_grid(24)
    x, y, z = grid.coordinates()
    a = np.array([0.3, -1.7, 2.2])
    phi = to_device(a[0] * x + a[1] * y + a[2] * z + 0.4, device)
    out = wp.zeros(grid.shape, dtype=wp.vec3, device=device)
    launch_central_gradient(phi, out, spacing=grid.spacing)
    g = interior(out.numpy(), 1)
    np.testing.assert_allclose(g.reshape(-1, 3), np.broadcast_to(a, (g.size // 3, 3)),
                               rtol=0, atol=2e-5 * np.abs(a).max() / grid.spacing)


def test_upwind_gradient_magnitude_of_sphere_sdf_is_one(device):
    grid = cube_grid(48)
    d = sphere_sdf(grid, (0.05, -0.02, 0.01), 0.5)
    phi = to_device(d, device)
    for speed in (1.0, -1.0):
        out = wp.zeros(grid.shape, dtype=float, device=device)
        launch_upwind_gradient_norm(phi, out, spacing=grid.spacing, speed=speed)
        r = interior(d + 0.5, 2)
        g = interior(out.numpy(), 2)
        away = r > 8 * grid.spacing  # a first-order stencil is ~6% off here
        assert np.max(np.abs(g[away] - 1.0)) < 0.01


def test_upwind_gradient_picks_the_upwind_side():
    # A kink |x| has slopes -1 and +1: an expanding front (speed > 0) sees the upwind slope 1
    # at the kink, a shrinking one sees 0 there, which a central or one-sided stencil would miss.
    grid = cube_grid(20)
    x, _, _ = grid.coordinates()
    phi = to_device(np.abs(x), "cpu")
    out = wp.zeros(grid.shape, dtype=float, device="cpu")
    i0 = grid.shape[0] // 2
    launch_upwind_gradient_norm(phi, out, spacing=grid.spacing, speed=1.0)
    assert out.numpy()[i0, 5, 5] == pytest.approx(0.0, abs=1e-6)
    launch_upwind_gradient_norm(phi, out, spacing=grid.spacing, speed=-1.0)
    assert out.numpy()[i0, 5, 5] == pytest.approx(1.0, abs=1e-5)


def curvature_error(n, radius, device):
    grid = cube_grid(n)
    d = sphere_sdf(grid, (0.0, 0.0, 0.0), radius)
    phi = to_device(d, device)
    out = wp.zeros(grid.shape, dtype=float, device=device)
    launch_curvature_term(phi, out, spacing=grid.spacing)
    band = np.abs(d) < grid.spacing
    r = d[band] + radius
    return np.max(np.abs(out.numpy()[band] - 2.0 / r)) * radius


@pytest.mark.parametrize("radius", [0.3, 0.5, 0.7])
def test_curvature_of_sphere_converges_second_order(device, radius):
    coarse = curvature_error(32, radius, device)
    fine = curvature_error(64, radius, device)
    order = np.log2(coarse / fine)
    assert fine < 0.02
    assert 1.7 < order < 2.6, (coarse, fine, order)


def test_curvature_is_capped_at_one_over_h(device):
    grid = cube_grid(16)
    d = sphere_sdf(grid, (0.0, 0.0, 0.0), 0.02)  # far below one cell
    out = wp.zeros(grid.shape, dtype=float, device=device)
    launch_curvature_term(to_device(d, device), out, spacing=grid.spacing)
    g = np.linalg.norm(np.gradient(d, grid.spacing), axis=0)
    assert np.all(np.abs(out.numpy()) <= g / grid.spacing * 1.0001 + 1e-6)


def numpy_normal(phi, h, idx):
    i, j, k = idx
    g = np.array([
        phi[i + 1, j, k] - phi[i - 1, j, k],
        phi[i, j + 1, k] - phi[i, j - 1, k],
        phi[i, j, k + 1] - phi[i, j, k - 1],
    ]) / (2 * h)
    return g / np.linalg.norm(g), np.linalg.norm(g)


def test_divergence_of_n_minus_v_is_zero_away_from_constraints_and_exact_at_one(device):
    grid = cube_grid(32)
    h = grid.spacing
    d = sphere_sdf(grid, (0.0, 0.0, 0.0), 0.6).astype(np.float32)
    phi = to_device(d, device)
    # One ray's intersection on the sphere and a normal tilted 20 degrees from the truth.
    x = 0.6 * np.array([0.48, 0.6, 0.64]) / np.linalg.norm([0.48, 0.6, 0.64])
    n_true = x / 0.6
    tilt = np.cross(n_true, [0.0, 0.0, 1.0])
    tilt /= np.linalg.norm(tilt)
    a = np.radians(20)
    n_given = np.cos(a) * n_true + np.sin(a) * tilt
    hits = wp.array([x], dtype=wp.vec3, device=device)
    active = wp.array([1], dtype=int, device=device)
    normals = wp.array([n_given], dtype=wp.vec3, device=device)
    owner = wp.zeros(grid.shape, dtype=int, device=device)
    dist = wp.zeros(grid.shape, dtype=float, device=device)
    launch_claim_normals(hits, active, dist, owner, origin=origin_of(grid), spacing=h, radius=h)
    own = owner.numpy()
    owned = np.argwhere(own == 0)
    node_pos = grid.origin + h * owned
    assert len(owned) >= 1
    assert np.all(np.linalg.norm(node_pos - x, axis=1) <= h * (1 + 1e-6))
    # the unowned six-neighbours of owned nodes, and they alone, carry the neighbour mark
    marked = np.zeros(grid.shape, dtype=bool)
    for i, j, k in owned:
        for axis in range(3):
            for step in (-1, 1):
                q = [i, j, k]
                q[axis] += step
                marked[tuple(q)] = True
    marked &= own != 0
    assert np.array_equal(own == NEIGHBOUR_OWNED, marked)
    assert np.all((own == 0) | (own == NO_OWNER) | marked)

    gauss = wp.zeros(grid.shape, dtype=float, device=device)
    out = wp.zeros(grid.shape, dtype=float, device=device)
    launch_flow_step(phi, owner, normals, gauss, out, spacing=h, dt=1.0, normal_weight=1.0)
    rate = out.numpy() - d

    # Exactly zero at every node more than one cell from an owned node.
    near = np.zeros(grid.shape, dtype=bool)
    for i, j, k in owned:
        near[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2, max(k - 1, 0):k + 2] = True
    assert np.all(rate[~near] == 0.0)

    # At the node just beyond an owned node along +x: |grad phi| * div(n - V), by hand.
    i, j, k = owned[0]
    target = (i - 1, j, k)
    nb = (i, j, k)
    n_nb, _ = numpy_normal(d, h, nb)
    _, g_target = numpy_normal(d, h, target)
    expected = g_target * (n_nb - n_given)[0] / (2 * h)
    # Other neighbours of the target may be owned too: add their contributions.
    for axis in range(3):
        for sign in (-1, 1):
            q = list(target)
            q[axis] += sign
            q = tuple(q)
            if q == nb or own[q] != 0:
                continue
            n_q, _ = numpy_normal(d, h, q)
            expected += sign * g_target * (n_q - n_given)[axis] / (2 * h)
    assert rate[target] == pytest.approx(expected, rel=1e-3)
    assert abs(expected) > 0.1  # the tilt produces a real force


def test_nearest_intersection_owns_overlapping_balls(device):
    grid = cube_grid(16)
    h = grid.spacing
    node = grid.origin + h * np.array([8, 8, 8])
    hits = wp.array([node + [0.6 * h, 0, 0], node + [0.3 * h, 0, 0], node + [-0.3 * h, 0, 0]],
                    dtype=wp.vec3, device=device)
    active = wp.array([1, 1, 1], dtype=int, device=device)
    owner = wp.zeros(grid.shape, dtype=int, device=device)
    dist = wp.zeros(grid.shape, dtype=float, device=device)
    launch_claim_normals(hits, active, dist, owner, origin=origin_of(grid), spacing=h, radius=h)
    own = owner.numpy()
    assert own[8, 8, 8] == 1  # rays 1 and 2 tie at 0.3 h: the lower index wins
    assert own[9, 8, 8] == 0  # 0.4 h from ray 0, 0.7 h from ray 1
    assert own[7, 8, 8] == 2
    active = wp.array([0, 0, 0], dtype=int, device=device)
    launch_claim_normals(hits, active, dist, owner, origin=origin_of(grid), spacing=h, radius=h)
    assert np.all(owner.numpy() == NO_OWNER)


@pytest.mark.parametrize("eps_cells", [1.0, 1.7])
def test_gaussian_matches_the_closed_form_maximum(device, eps_cells):
    grid = cube_grid(24)
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.9, 0.9, size=(15, 3))
    pts[0] = grid.origin + grid.spacing * 3  # on a node
    eps = eps_cells * grid.spacing
    g = wp.zeros(grid.shape, dtype=float, device=device)
    launch_gaussian(wp.array(pts, dtype=wp.vec3, device=device), g, origin=origin_of(grid),
                    spacing=grid.spacing, eps=eps)
    x, y, z = grid.coordinates()
    nodes = np.stack([x, y, z], axis=-1)
    exact = np.zeros(grid.shape)
    for p in pts:
        exact = np.maximum(exact, np.exp(-np.sum((nodes - p) ** 2, axis=-1) / (2 * eps * eps)))
    assert np.max(np.abs(g.numpy() - exact)) < 2e-5


def got_max_is_bounded(g: np.ndarray) -> bool:
    """A dense cloud pulls as one point does: G never exceeds 1."""
    return float(g.max()) <= 1.0 + 1e-6


def test_gaussian_handles_many_points(device):
    grid = cube_grid(32)
    pts = np.random.default_rng(0).uniform(-1.2, 1.2, size=(100_000, 3))
    g = wp.zeros(grid.shape, dtype=float, device=device)
    launch_gaussian(wp.array(pts, dtype=wp.vec3, device=device), g, origin=origin_of(grid),
                    spacing=grid.spacing, eps=grid.spacing)
    # Brute force over all the points at a sample of nodes.
    rng = np.random.default_rng(1)
    idx = rng.integers(0, np.array(grid.shape), size=(300, 3))
    nodes = grid.origin + grid.spacing * idx
    r2 = np.sum((nodes[:, None, :] - pts[None, :, :]) ** 2, axis=-1)
    exact = np.exp(-r2 / (2 * grid.spacing**2)).max(axis=1)
    assert got_max_is_bounded(g.numpy())
    got = g.numpy()[idx[:, 0], idx[:, 1], idx[:, 2]]
    np.testing.assert_allclose(got, exact, rtol=1e-4, atol=1e-4)


def test_point_decay_is_exact(device):
    grid = cube_grid(16)
    rng = np.random.default_rng(1)
    phi0 = rng.normal(size=grid.shape).astype(np.float32)
    gauss = rng.uniform(0, 2, size=grid.shape).astype(np.float32)
    owner = wp.full(grid.shape, NO_OWNER, dtype=int, device=device)
    normals = wp.zeros(0, dtype=wp.vec3, device=device)
    out = wp.zeros(grid.shape, dtype=float, device=device)
    w, dt = 37.0, 0.013
    launch_flow_step(to_device(phi0, device), owner, normals, to_device(gauss, device), out,
                     spacing=grid.spacing, dt=dt, normal_weight=0.0, alpha=0.0, point_weight=w)
    np.testing.assert_allclose(out.numpy(), phi0 * np.exp(-w * gauss * dt), rtol=2e-6, atol=1e-7)


@pytest.mark.parametrize("shape", [(9, 7, 5), (3, 1030, 4), (40, 40, 60)],
                         ids=["bit-packed", "linear", "two-threads"])
def test_band_step_equals_the_dense_step_on_the_band_and_leaves_the_rest(device, shape):
    # (3, 1030, 4) is too wide to bit-pack a node: the band stores linear indices instead;
    # (40, 40, 60) has more band nodes than SPLIT_MIN: two CPU threads take half each
    rng = np.random.default_rng(3)
    phi0 = rng.normal(size=shape).astype(np.float32)
    gauss = rng.uniform(0, 2, size=shape).astype(np.float32)
    owner = wp.full(shape, NO_OWNER, dtype=int, device=device)
    normals = wp.zeros(0, dtype=wp.vec3, device=device)
    phi = to_device(phi0, device)
    band = wp.zeros(phi0.size, dtype=int, device=device)
    count = wp.zeros(1, dtype=int, device=device)
    launch_build_band(phi, band, count, width=0.5)
    inside = np.abs(phi0) <= 0.5
    assert count.numpy()[0] == inside.sum()
    if phi0.size > 40_000:
        assert inside.sum() > SPLIT_MIN
    weights = dict(spacing=0.1, dt=1e-3, alpha=0.3, point_weight=5.0)
    dense = wp.zeros(shape, dtype=float, device=device)
    launch_flow_step(phi, owner, normals, to_device(gauss, device), dense, **weights)
    sparse = wp.full(shape, 7.0, dtype=float, device=device)
    launch_flow_step_band(phi, owner, normals, to_device(gauss, device), band, count, sparse,
                          size=phi0.size, **weights)
    got = sparse.numpy()
    np.testing.assert_array_equal(got[inside], dense.numpy()[inside])
    assert np.all(got[~inside] == 7.0)


def test_rays_hit_a_sphere_within_a_twentieth_of_a_cell_and_misses_are_flagged(device):
    grid = cube_grid(48)
    h = grid.spacing
    centre = np.array([0.05, -0.03, 0.02])
    radius = 0.55
    phi = to_device(sphere_sdf(grid, centre, radius), device)
    rng = np.random.default_rng(7)
    targets = rng.normal(size=(40, 3))
    targets /= np.linalg.norm(targets, axis=1, keepdims=True)
    eyes = centre + 3.0 * targets + rng.normal(scale=0.3, size=(40, 3))
    aims = centre + 0.5 * radius * rng.uniform(-1, 1, size=(40, 3))
    dirs = aims - eyes
    # Rays that miss: aimed past the sphere, and away from it.
    miss_eyes = np.array([[3.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 0.0, 0.3]])
    miss_dirs = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    eyes = np.vstack([eyes, miss_eyes])
    dirs = np.vstack([dirs, miss_dirs])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    m = len(eyes)
    hits = wp.zeros(m, dtype=wp.vec3, device=device)
    active = wp.zeros(m, dtype=int, device=device)
    normals = wp.zeros(m, dtype=wp.vec3, device=device)
    light = np.tile([0.0, 0.0, 1.0], (m, 1))
    launch_intersect(phi, wp.array(eyes, dtype=wp.vec3, device=device),
                     wp.array(dirs, dtype=wp.vec3, device=device),
                     wp.zeros(m, dtype=int, device=device),
                     wp.array(light, dtype=wp.vec3, device=device), hits, active, normals,
                     origin=origin_of(grid), spacing=h)
    act = active.numpy()
    assert np.all(act[:40] == 1)
    assert np.all(act[40:] == 0)
    # Exact first intersection of each ray with the sphere.
    oc = eyes[:40] - centre
    b = np.einsum("ij,ij->i", oc, dirs[:40])
    t = -b - np.sqrt(b * b - (np.einsum("ij,ij->i", oc, oc) - radius**2))
    exact = eyes[:40] + t[:, None] * dirs[:40]
    err = np.linalg.norm(hits.numpy()[:40] - exact, axis=1)
    assert err.max() < 0.05 * h
    # Directional light: N = normalize(L - r).
    expected = light[:40] - dirs[:40]
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(normals.numpy()[:40], expected, atol=1e-5)


def test_point_light_and_flash_normals_follow_the_intersection(device):
    grid = cube_grid(32)
    phi = to_device(sphere_sdf(grid, (0.0, 0.0, 0.0), 0.5), device)
    eyes = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, 3.0]])
    dirs = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    lamp = np.array([[1.0, 0.0, 2.0], [0.0, 0.0, 0.0]])
    hits = wp.zeros(2, dtype=wp.vec3, device=device)
    active = wp.zeros(2, dtype=int, device=device)
    normals = wp.zeros(2, dtype=wp.vec3, device=device)
    launch_intersect(phi, wp.array(eyes, dtype=wp.vec3, device=device),
                     wp.array(dirs, dtype=wp.vec3, device=device),
                     wp.array([1, 2], dtype=int, device=device),
                     wp.array(lamp, dtype=wp.vec3, device=device), hits, active, normals,
                     origin=origin_of(grid), spacing=grid.spacing)
    x = hits.numpy()[0]
    to_lamp = (lamp[0] - x) / np.linalg.norm(lamp[0] - x)
    expected = to_lamp - dirs[0]
    np.testing.assert_allclose(normals.numpy()[0], expected / np.linalg.norm(expected),
                               atol=1e-5)
    np.testing.assert_allclose(normals.numpy()[1], -dirs[1], atol=1e-6)


def test_plane_and_bend_keep_the_zero_set_on_the_points(device):
    grid = cube_grid(32)
    h = grid.spacing
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    p0 = np.array([0.1, 0.0, -0.1])
    phi = wp.zeros(grid.shape, dtype=float, device=device)
    launch_plane(phi, origin=origin_of(grid), spacing=h, point=tuple(p0), normal=tuple(n))
    x, y, z = grid.coordinates()
    plane = (x - p0[0]) * n[0] + (y - p0[1]) * n[1] + (z - p0[2]) * n[2]
    np.testing.assert_allclose(phi.numpy(), plane, atol=1e-5)
    # Bend by c * d with d the distance to the plane point p0: the zero set stays at p0,
    # and moves by c * d elsewhere (|grad phi| = 1 for a plane).
    dist = to_device(np.sqrt((x - p0[0]) ** 2 + (y - p0[1]) ** 2 + (z - p0[2]) ** 2), device)
    out = wp.zeros(grid.shape, dtype=float, device=device)
    launch_bend(phi, dist, out, spacing=h, c=0.5)
    bent = interior(out.numpy(), 1)
    expected = interior(plane - 0.5 * dist.numpy(), 1)
    np.testing.assert_allclose(bent, expected, atol=1e-5)


@pytest.mark.parametrize("degree", [0, 1, 4])
def test_height_field_matches_the_monomial_sum(device, degree):
    # an uneven box, so that swapped axes would show; the NumPy side sums monomials directly
    grid = Grid.from_bounds(np.array([-1.0, -0.5, -0.8]), np.array([1.0, 0.7, 0.6]),
                            resolution=24)
    frame = plane_frame(np.array([0.3, -0.4, 1.0]))
    powers = monomials(degree)
    coeffs = np.random.default_rng(degree).normal(scale=0.2, size=len(powers))
    fit = HeightFit(np.array([0.1, 0.05, -0.2]), frame, 0.9, powers, coeffs)
    phi = wp.zeros(grid.shape, dtype=float, device=device)
    launch_height_field(phi, wp.array(fit.coefficient_matrix().astype(np.float32),
                                      dtype=float, device=device),
                        origin=origin_of(grid), spacing=grid.spacing,
                        point=tuple(fit.point), axes=tuple(tuple(r) for r in frame),
                        scale=fit.scale)
    nodes = np.stack(grid.coordinates(), axis=-1).reshape(-1, 3)
    np.testing.assert_allclose(phi.numpy().reshape(-1), fit.evaluate(nodes), atol=2e-5)
    if degree == 0:  # a plane offset along its normal by scale * c: the exact distance
        exact = (nodes - fit.point) @ frame[2] - fit.scale * coeffs[0]
        np.testing.assert_allclose(phi.numpy().reshape(-1), exact, atol=1e-5)

