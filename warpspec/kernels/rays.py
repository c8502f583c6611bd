"""Specular rays against the zero set, and the reductions behind the per-iteration measures.

A ray is clipped to the domain box, marched with steps of at most ``h/2`` on trilinearly
interpolated ``phi``, and its first crossing from ``phi > 0`` to ``phi <= 0`` is refined by
bisection (docs/DESIGN.md section 5). The constraint normal is then computed for the light model of
its camera: ``N = normalize(L - r)``, ``L`` toward the light (a point light is evaluated at the
intersection), or ``N = -r`` for a flash at the camera.
"""

from __future__ import annotations

import warp as wp

from .differences import band_slot, central_gradient, unit_normal

wp.set_module_options({"enable_backward": False})

__all__ = [
    "MEASURE_SLOTS",
    "launch_intersect",
    "launch_measures",
]

LIGHT_DIRECTIONAL = wp.constant(0)
LIGHT_POINT = wp.constant(1)
LIGHT_CAMERA = wp.constant(2)
BISECTIONS = wp.constant(30)

# Slots of the float64 accumulator filled by launch_measures.
MEASURE_SLOTS = {
    "normal_error_sum": 0,
    "active": 1,
    "misses": 2,
    "point_abs_sum": 3,
    "energy_normal": 4,
    "energy_smooth": 5,
    "nonfinite": 6,
}
NUM_SLOTS = 7


@wp.func
def grid_coordinate(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> wp.vec3:
    """Continuous grid index of a world point, clamped to the grid."""
    q = (x - origin) / h
    return wp.vec3(
        wp.clamp(q[0], 0.0, float(phi.shape[0] - 1)),
        wp.clamp(q[1], 0.0, float(phi.shape[1] - 1)),
        wp.clamp(q[2], 0.0, float(phi.shape[2] - 1)),
    )


@wp.func
def cell_corner(phi: wp.array3d[float], q: wp.vec3) -> wp.vec3i:
    """Lowest node of the cell that holds the continuous index ``q``."""
    return wp.vec3i(
        wp.min(int(q[0]), phi.shape[0] - 2),
        wp.min(int(q[1]), phi.shape[1] - 2),
        wp.min(int(q[2]), phi.shape[2] - 2),
    )


@wp.func
def corner_weight(f: wp.vec3, c: int) -> float:
    """Trilinear weight of corner ``c`` (bits: x, y, z) for fractions ``f`` in the cell."""
    w = wp.where((c & 1) == 1, f[0], 1.0 - f[0])
    w *= wp.where(((c >> 1) & 1) == 1, f[1], 1.0 - f[1])
    w *= wp.where(((c >> 2) & 1) == 1, f[2], 1.0 - f[2])
    return w


@wp.func
def trilinear(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> float:
    """Trilinear interpolation of a nodal field at a world point (clamped to the grid)."""
    q = grid_coordinate(phi, origin, h, x)
    n = cell_corner(phi, q)
    f = q - wp.vec3(float(n[0]), float(n[1]), float(n[2]))
    value = float(0.0)
    for c in range(8):
        value += corner_weight(f, c) * phi[n[0] + (c & 1), n[1] + ((c >> 1) & 1),
                                           n[2] + ((c >> 2) & 1)]
    return value


@wp.func
def trilinear_gradient(phi: wp.array3d[float], origin: wp.vec3, h: float, x: wp.vec3) -> wp.vec3:
    """Trilinear interpolation of the nodal central-difference gradients at a world point."""
    q = grid_coordinate(phi, origin, h, x)
    n = cell_corner(phi, q)
    f = q - wp.vec3(float(n[0]), float(n[1]), float(n[2]))
    g = wp.vec3(0.0, 0.0, 0.0)
    for c in range(8):
        g += corner_weight(f, c) * central_gradient(phi, n[0] + (c & 1), n[1] + ((c >> 1) & 1),
                                                     n[2] + ((c >> 2) & 1), 0.5 / h)
    return g


@wp.func
def slab(o: wp.vec3, d: wp.vec3, lo: wp.vec3, hi: wp.vec3) -> wp.vec2:
    """Parameter interval ``[t0, t1]`` of the ray ``o + t d`` inside a box (empty: t0 > t1)."""
    t0 = float(0.0)
    t1 = 1.0e30
    for a in range(3):
        if wp.abs(d[a]) < 1.0e-12:
            if o[a] < lo[a] or o[a] > hi[a]:
                t0 = 1.0e30
                t1 = -1.0e30
        else:
            ta = (lo[a] - o[a]) / d[a]
            tb = (hi[a] - o[a]) / d[a]
            t0 = wp.max(t0, wp.min(ta, tb))
            t1 = wp.min(t1, wp.max(ta, tb))
    return wp.vec2(t0, t1)


@wp.func
def reflection_normal(code: int, light: wp.vec3, r: wp.vec3, x: wp.vec3) -> wp.vec3:
    """Normal demanded by the reflection law at ``x`` for a ray of direction ``r``."""
    if code == LIGHT_CAMERA:
        return -r
    to_light = light
    if code == LIGHT_POINT:
        to_light = wp.normalize(light - x)
    return wp.normalize(to_light - r)


@wp.kernel
def intersect(
    phi: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    ray_origin: wp.array[wp.vec3],
    ray_dir: wp.array[wp.vec3],
    light_code: wp.array[int],
    light_vec: wp.array[wp.vec3],
    hits: wp.array[wp.vec3],
    active: wp.array[int],
    normals: wp.array[wp.vec3],
):
    """March each ray to its first ``+ -> -`` crossing of the zero set and refine it."""
    r = wp.tid()
    o = ray_origin[r]
    d = ray_dir[r]
    hi = origin + h * wp.vec3(
        float(phi.shape[0] - 1), float(phi.shape[1] - 1), float(phi.shape[2] - 1)
    )
    span = slab(o, d, origin, hi)
    active[r] = 0
    if span[0] > span[1]:
        return
    steps = int(wp.ceil((span[1] - span[0]) / (0.5 * h)))
    steps = wp.max(steps, 1)
    dt = (span[1] - span[0]) / float(steps)
    t_prev = span[0]
    f_prev = trilinear(phi, origin, h, o + t_prev * d)
    for s in range(1, steps + 1):
        t = span[0] + float(s) * dt
        f = trilinear(phi, origin, h, o + t * d)
        if f_prev > 0.0 and f <= 0.0:
            a = t_prev
            b = t
            for _ in range(BISECTIONS):
                m = 0.5 * (a + b)
                if trilinear(phi, origin, h, o + m * d) > 0.0:
                    a = m
                else:
                    b = m
            x = o + (0.5 * (a + b)) * d
            hits[r] = x
            active[r] = 1
            normals[r] = reflection_normal(light_code[r], light_vec[r], d, x)
            return
        t_prev = t
        f_prev = f


@wp.kernel
def measure_rays(
    phi: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    hits: wp.array[wp.vec3],
    active: wp.array[int],
    normals: wp.array[wp.vec3],
    sums: wp.array[wp.float64],
):
    """Accumulate ``1 - N_i . n(x_i)`` over active rays, their count and the misses."""
    r = wp.tid()
    if active[r] == 0:
        wp.atomic_add(sums, 2, wp.float64(1.0))
        return
    g = trilinear_gradient(phi, origin, h, hits[r])
    n = wp.normalize(g)
    wp.atomic_add(sums, 0, wp.float64(1.0 - wp.dot(normals[r], n)))
    wp.atomic_add(sums, 1, wp.float64(1.0))


@wp.kernel
def measure_points(
    phi: wp.array3d[float],
    origin: wp.vec3,
    h: float,
    points: wp.array[wp.vec3],
    sums: wp.array[wp.float64],
):
    """Accumulate ``|phi(y)|`` over the point constraints."""
    p = wp.tid()
    wp.atomic_add(sums, 3, wp.float64(wp.abs(trilinear(phi, origin, h, points[p]))))


@wp.func
def measure_node(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    i: int,
    j: int,
    k: int,
    h: float,
    sums: wp.array[wp.float64],
):
    """One node's share of ``E_N`` and the surface area, or of the non-finite count.

    Surface integrals use the smeared delta ``(1 + cos(pi phi / w)) / (2 w)``, ``w = 1.5 h``.
    """
    c = phi[i, j, k]
    if not wp.isfinite(c):
        wp.atomic_add(sums, 6, wp.float64(1.0))
        return
    width = 1.5 * h
    if wp.abs(c) >= width:
        return
    delta = (1.0 + wp.cos(wp.pi * c / width)) / (2.0 * width)
    grad = wp.length(central_gradient(phi, i, j, k, 0.5 / h))
    ds = delta * grad * h * h * h
    wp.atomic_add(sums, 5, wp.float64(ds))
    o = owner[i, j, k]
    if o >= 0 and o < normals.shape[0]:
        n = unit_normal(phi, i, j, k, 0.5 / h)
        wp.atomic_add(sums, 4, wp.float64((1.0 - wp.dot(normals[o], n)) * ds))


@wp.kernel
def measure_grid(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    h: float,
    sums: wp.array[wp.float64],
):
    """Grid integrals over every node: ``E_N``, the surface area, non-finite values."""
    i, j, k = wp.tid()
    measure_node(phi, owner, normals, i, j, k, h, sums)


@wp.kernel
def measure_band(
    phi: wp.array3d[float],
    owner: wp.array3d[int],
    normals: wp.array[wp.vec3],
    band: wp.array[int],
    count: wp.array[int],
    h: float,
    sums: wp.array[wp.float64],
):
    """Grid integrals over the nodes of a narrow band (the only ones that change)."""
    n = band_slot(band, count, wp.tid(), 0, wp.vec3i(phi.shape[0], phi.shape[1], phi.shape[2]))
    if n[0] < 0:
        return
    measure_node(phi, owner, normals, n[0], n[1], n[2], h, sums)


def launch_intersect(
    phi: wp.array,
    ray_origin: wp.array,
    ray_dir: wp.array,
    light_code: wp.array,
    light_vec: wp.array,
    hits: wp.array,
    active: wp.array,
    normals: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
) -> None:
    """Intersect every ray with the zero set; write hit points, active flags and normals.

    Args:
        phi: Level set.
        ray_origin: Ray origins (camera centres).
        ray_dir: Unit ray directions, from the camera into the scene.
        light_code: Light model per ray (0 directional, 1 point, 2 camera flash).
        light_vec: Direction toward the light (directional) or its position (point).
        hits: Output intersection points.
        active: Output flags, 1 where the ray crosses the zero set from outside, else 0.
        normals: Output constraint normals (left unchanged for inactive rays).
        origin: World position of node ``(0, 0, 0)``.
        spacing: Grid spacing ``h``.
    """
    if ray_origin.shape[0] == 0:
        return
    wp.launch(
        intersect,
        dim=ray_origin.shape[0],
        inputs=[phi, wp.vec3(*origin), float(spacing), ray_origin, ray_dir, light_code,
                light_vec],
        outputs=[hits, active, normals],
        device=phi.device,
    )


def launch_measures(
    phi: wp.array,
    owner: wp.array,
    normals: wp.array,
    hits: wp.array,
    active: wp.array,
    points: wp.array,
    sums: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    band: wp.array | None = None,
    count: wp.array | None = None,
    size: int = 0,
) -> None:
    """Zero ``sums`` (float64, :data:`MEASURE_SLOTS`) and accumulate every measure into it.

    With ``band`` (and its ``count`` and launch ``size``), the grid integrals visit only the
    band's nodes, which hold the whole zero set and every node that changes.
    """
    sums.zero_()
    o = wp.vec3(*origin)
    h = float(spacing)
    if hits.shape[0] > 0:
        wp.launch(measure_rays, dim=hits.shape[0], inputs=[phi, o, h, hits, active, normals],
                  outputs=[sums], device=phi.device)
    if points.shape[0] > 0:
        wp.launch(measure_points, dim=points.shape[0], inputs=[phi, o, h, points],
                  outputs=[sums], device=phi.device)
    if band is None:
        wp.launch(measure_grid, dim=phi.shape, inputs=[phi, owner, normals, h],
                  outputs=[sums], device=phi.device)
    elif size > 0:
        wp.launch(measure_band, dim=size, inputs=[phi, owner, normals, band, count, h],
                  outputs=[sums], device=phi.device)
