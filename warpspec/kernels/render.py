"""Rendering photographs of a scene with Warp's mesh ray queries (the rendered-photo bench).

Two passes over the samples of one image (``ss x ss`` samples per pixel, COLMAP's pixel
convention: pixel ``(col, row)`` covers ``[col, col + 1] x [row, row + 1]``):

- :func:`launch_trace` casts each sample's ray against one :class:`warp.Mesh` (the object's
  triangles first, then the room's) and returns the hit distance, the face and the normal
  interpolated from the vertex normals;
- :func:`launch_shade` shades each hit: Lambert plus a Blinn-Phong lobe on the object,
  a procedural value-noise texture and small emissive spots on the room, a shadow ray toward
  lamps and suns that only the object can block (a flash at the camera casts no visible shadow).

:func:`launch_visible` tells which 3D points each camera sees (nothing of the mesh between the
camera and the point), for the observations of the COLMAP model.
"""

from __future__ import annotations

import warp as wp

from .. import geometry

wp.set_module_options({"enable_backward": False})

__all__ = ["LIGHT_CAMERA", "LIGHT_DIRECTIONAL", "LIGHT_POINT", "launch_shade", "launch_trace",
           "launch_visible"]

LIGHT_DIRECTIONAL = wp.constant(geometry.LIGHT_DIRECTIONAL)
LIGHT_POINT = wp.constant(geometry.LIGHT_POINT)
LIGHT_CAMERA = wp.constant(geometry.LIGHT_CAMERA)
NO_HIT = -1


@wp.kernel
def _trace(
    mesh: wp.uint64,
    normals: wp.array(dtype=wp.vec3),
    indices: wp.array(dtype=int),
    centre: wp.vec3,
    m_inv: wp.mat33,
    ss: int,
    max_t: float,
    hit_t: wp.array2d(dtype=float),
    hit_face: wp.array2d(dtype=int),
    hit_normal: wp.array2d(dtype=wp.vec3),
    ray_dir: wp.array2d(dtype=wp.vec3),
):
    row, col = wp.tid()
    u = (float(col) + 0.5) / float(ss)
    v = (float(row) + 0.5) / float(ss)
    d = wp.normalize(m_inv @ wp.vec3(u, v, 1.0))
    ray_dir[row, col] = d
    q = wp.mesh_query_ray(mesh, centre, d, max_t)
    if q.result:
        f = q.face
        n0 = normals[indices[3 * f + 0]]
        n1 = normals[indices[3 * f + 1]]
        n2 = normals[indices[3 * f + 2]]
        n = q.u * n0 + q.v * n1 + (1.0 - q.u - q.v) * n2
        if wp.length(n) > 0.0:
            n = wp.normalize(n)
        else:
            n = q.normal
        hit_t[row, col] = q.t
        hit_face[row, col] = f
        hit_normal[row, col] = n
    else:
        hit_t[row, col] = max_t
        hit_face[row, col] = NO_HIT
        hit_normal[row, col] = wp.vec3(0.0, 0.0, 0.0)


@wp.func
def _hash(i: int, j: int, k: int, seed: int) -> float:
    """A pseudo-random number in [0, 1) for a lattice cell."""
    h = i * 73856093 ^ j * 19349663 ^ k * 83492791 ^ seed * 2654435
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return float(h & 65535) / 65536.0


@wp.func
def _value_noise(p: wp.vec3, seed: int) -> float:
    """Trilinear value noise with one random value per unit lattice node."""
    fx = wp.floor(p[0])
    fy = wp.floor(p[1])
    fz = wp.floor(p[2])
    i = int(fx)
    j = int(fy)
    k = int(fz)
    tx = p[0] - fx
    ty = p[1] - fy
    tz = p[2] - fz
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    tz = tz * tz * (3.0 - 2.0 * tz)
    c00 = wp.lerp(_hash(i, j, k, seed), _hash(i + 1, j, k, seed), tx)
    c10 = wp.lerp(_hash(i, j + 1, k, seed), _hash(i + 1, j + 1, k, seed), tx)
    c01 = wp.lerp(_hash(i, j, k + 1, seed), _hash(i + 1, j, k + 1, seed), tx)
    c11 = wp.lerp(_hash(i, j + 1, k + 1, seed), _hash(i + 1, j + 1, k + 1, seed), tx)
    return wp.lerp(wp.lerp(c00, c10, ty), wp.lerp(c01, c11, ty), tz)


@wp.kernel
def _shade(
    mesh: wp.uint64,
    centre: wp.vec3,
    ray_dir: wp.array2d(dtype=wp.vec3),
    hit_t: wp.array2d(dtype=float),
    hit_face: wp.array2d(dtype=int),
    hit_normal: wp.array2d(dtype=wp.vec3),
    object_faces: int,
    light_type: int,
    light_vec: wp.vec3,
    light_ref: float,
    shininess: float,
    specular: float,
    object_albedo: wp.vec3,
    ambient: float,
    texture_scale: float,
    seed: int,
    spots: wp.array(dtype=wp.vec3),
    spot_radius: wp.array(dtype=float),
    spot_value: wp.array(dtype=float),
    eps: float,
    out: wp.array2d(dtype=wp.vec3),
):
    row, col = wp.tid()
    f = hit_face[row, col]
    if f == NO_HIT:
        out[row, col] = wp.vec3(0.0, 0.0, 0.0)
        return
    d = ray_dir[row, col]
    p = centre + hit_t[row, col] * d
    n = hit_normal[row, col]
    if wp.dot(n, d) > 0.0:
        n = -n  # seen from behind (an open patch, the room's walls): face the camera
    # Unit vector toward the light and the irradiance there (1 at distance light_ref).
    to_light = light_vec
    irradiance = float(1.0)
    light_dist = float(1.0e30)
    if light_type != LIGHT_DIRECTIONAL:
        source = light_vec
        if light_type == LIGHT_CAMERA:
            source = centre
        w = source - p
        light_dist = wp.length(w)
        to_light = w / light_dist
        irradiance = (light_ref * light_ref) / (light_dist * light_dist)
    cos_i = wp.max(wp.dot(n, to_light), 0.0)
    lit = float(1.0)
    if light_type != LIGHT_CAMERA and cos_i > 0.0:
        s = wp.mesh_query_ray(mesh, p + eps * n, to_light, light_dist - 2.0 * eps)
        if s.result and s.face < object_faces:
            lit = 0.0  # only the object casts shadows; the room is the enclosure
    colour = wp.vec3(0.0, 0.0, 0.0)
    if f < object_faces:
        h = wp.normalize(to_light - d)
        lobe = wp.pow(wp.max(wp.dot(n, h), 0.0), shininess)
        colour = object_albedo * (ambient + lit * irradiance * cos_i)
        colour = colour + wp.vec3(1.0, 1.0, 1.0) * (lit * irradiance * specular * lobe)
    else:
        q = p / texture_scale
        t = 0.55 * _value_noise(q, seed) + 0.3 * _value_noise(3.1 * q, seed + 1)
        t = t + 0.15 * _value_noise(9.7 * q, seed + 2)
        albedo = 0.08 + 0.55 * t
        tint = wp.vec3(1.0, 0.9 + 0.2 * _value_noise(0.5 * q, seed + 3), 0.8)
        colour = albedo * tint * (ambient + lit * irradiance * cos_i)
        for k in range(spots.shape[0]):
            if wp.length(p - spots[k]) < spot_radius[k]:
                colour = wp.vec3(spot_value[k], spot_value[k], spot_value[k])
    out[row, col] = colour


@wp.kernel
def _visible(
    mesh: wp.uint64,
    centres: wp.array(dtype=wp.vec3),
    points: wp.array(dtype=wp.vec3),
    slack: float,
    seen: wp.array2d(dtype=int),
):
    c, k = wp.tid()
    w = points[k] - centres[c]
    dist = wp.length(w)
    q = wp.mesh_query_ray(mesh, centres[c], w / dist, dist - slack)
    if q.result:
        seen[c, k] = 0
    else:
        seen[c, k] = 1


def launch_trace(mesh: wp.Mesh, normals: wp.array, centre, m_inv, *, width: int, height: int,
                 ss: int, max_t: float) -> tuple[wp.array, wp.array, wp.array, wp.array]:
    """Trace the ``ss x ss`` samples of every pixel of a ``width x height`` image.

    Args:
        mesh: The scene's mesh.
        normals: Its vertex normals.
        centre: The camera centre (3,).
        m_inv: ``sign(det M) M^-1`` of the camera ``P = [M | p4]`` (3x3), COLMAP's pixels.
        width: Image width in pixels.
        height: Image height in pixels.
        ss: Samples per pixel along each axis.
        max_t: The longest ray.

    Returns:
        Hit distance, face (-1: none), interpolated normal and ray direction per sample,
        arrays of shape ``(height * ss, width * ss)``.
    """
    device = mesh.device
    shape = (height * ss, width * ss)
    t = wp.empty(shape, dtype=float, device=device)
    face = wp.empty(shape, dtype=int, device=device)
    normal = wp.empty(shape, dtype=wp.vec3, device=device)
    direction = wp.empty(shape, dtype=wp.vec3, device=device)
    wp.launch(_trace, dim=shape, device=device,
              inputs=[mesh.id, normals, mesh.indices, wp.vec3(*map(float, centre)),
                      wp.mat33(*(float(x) for x in m_inv.ravel())), int(ss), float(max_t),
                      t, face, normal, direction])
    return t, face, normal, direction


def launch_shade(mesh: wp.Mesh, centre, direction: wp.array, t: wp.array, face: wp.array,
                 normal: wp.array, *, object_faces: int, light_type: int, light_vec,
                 light_ref: float, shininess: float, specular: float, object_albedo,
                 ambient: float, texture_scale: float, seed: int, spots: wp.array,
                 spot_radius: wp.array, spot_value: wp.array, eps: float) -> wp.array:
    """Shade traced samples; returns linear RGB per sample (values above 1 saturate later)."""
    device = mesh.device
    out = wp.empty(t.shape, dtype=wp.vec3, device=device)
    wp.launch(_shade, dim=t.shape, device=device,
              inputs=[mesh.id, wp.vec3(*map(float, centre)), direction, t, face, normal,
                      int(object_faces), int(light_type), wp.vec3(*map(float, light_vec)),
                      float(light_ref), float(shininess), float(specular),
                      wp.vec3(*map(float, object_albedo)), float(ambient),
                      float(texture_scale), int(seed), spots, spot_radius, spot_value,
                      float(eps), out])
    return out


def launch_visible(mesh: wp.Mesh, centres: wp.array, points: wp.array, *, slack: float
                   ) -> wp.array:
    """Whether each camera sees each point: ``(cameras, points)`` of 0/1 (occlusion only)."""
    device = mesh.device
    seen = wp.empty((centres.shape[0], points.shape[0]), dtype=int, device=device)
    if centres.shape[0] and points.shape[0]:
        wp.launch(_visible, dim=seen.shape, device=device,
                  inputs=[mesh.id, centres, points, float(slack), seen])
    return seen
