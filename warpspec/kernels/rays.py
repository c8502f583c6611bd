"""Specular rays against the zero set: intersection and the reflection law's normal.

A ray is clipped to the domain box, marched with steps of at most ``h/2`` on trilinearly
interpolated ``phi``, and its first crossing from ``phi > 0`` to ``phi <= 0`` is refined by
bisection (docs/DESIGN.md section 5). The constraint normal is then computed for the light model of
its camera: ``N = normalize(L - r)``, ``L`` toward the light (a point light is evaluated at the
intersection), or ``N = -r`` for a flash at the camera.
"""

from __future__ import annotations

import warp as wp

from .. import geometry
from .sampling import trilinear

wp.set_module_options({"enable_backward": False})

__all__ = [
    "BISECTIONS",
    "launch_intersect",
    "LIGHT_CAMERA",
    "LIGHT_DIRECTIONAL",
    "LIGHT_POINT",
    "reflection_normal",
    "slab",
]

LIGHT_DIRECTIONAL = wp.constant(geometry.LIGHT_DIRECTIONAL)

LIGHT_POINT = wp.constant(geometry.LIGHT_POINT)

LIGHT_CAMERA = wp.constant(geometry.LIGHT_CAMERA)

BISECTIONS = wp.constant(30)

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

@wp.func
def grid_span(phi: wp.array3d[float], origin: wp.vec3, h: float, o: wp.vec3,
              d: wp.vec3) -> wp.vec2:
    """Parameter interval of the ray ``o + t d`` inside the grid's box (empty: t0 > t1)."""
    hi = origin + h * wp.vec3(
        float(phi.shape[0] - 1), float(phi.shape[1] - 1), float(phi.shape[2] - 1)
    )
    return slab(o, d, origin, hi)


@wp.func
def bisect_crossing(phi: wp.array3d[float], origin: wp.vec3, h: float, o: wp.vec3,
                    d: wp.vec3, a: float, b: float) -> float:
    """The ray parameter of the ``+ -> -`` crossing between ``a`` (phi > 0) and ``b``."""
    for _ in range(BISECTIONS):
        m = 0.5 * (a + b)
        if trilinear(phi, origin, h, o + m * d) > 0.0:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


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
    span = grid_span(phi, origin, h, o, d)
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
            x = o + bisect_crossing(phi, origin, h, o, d, t_prev, t) * d
            hits[r] = x
            active[r] = 1
            normals[r] = reflection_normal(light_code[r], light_vec[r], d, x)
            return
        t_prev = t
        f_prev = f

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
