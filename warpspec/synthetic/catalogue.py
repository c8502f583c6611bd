"""The built-in synthetic scenes, by name (warpspec synth)."""

from __future__ import annotations

import inspect
import math
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import SceneError
from ..geometry import (
    CameraLight,
    DirectionalLight,
    LightModel,
    PointLight,
    _dot,
    _normalize,
    _points,
    reflect,
)
from ..options import DEFAULTS
from .cameras import Halfspace, Intrinsics, clip_mesh, spread_points
from .scenes import SyntheticScene, jitter_points, scene_from_path, scene_from_points
from .surfaces import (
    Blob,
    Cylinder,
    Ellipsoid,
    FreeformHeightField,
    Paraboloid,
    Revolution,
    Saddle,
    Sphere,
    Surface,
    Torus,
    _tangent_basis,
)

# --------------------------------------------------------------------------------------------
# Built-in scenes
# --------------------------------------------------------------------------------------------


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = math.pi * (3 - math.sqrt(5)) * i
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def octant(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """One eighth of the unit sphere (paper section 4.2).

    Unit sphere at the origin, patch ``x, y, z >= 0``; 24 highlights spread by farthest-point
    sampling over the patch at least 6 degrees from its rim, each seen by its own camera at
    distance 3 under the directional light ``normalize(1, 1, 1)``; point constraints
    ``(1,0,0), (0,1,0), (0,0,1)``; domain ``[-0.1, 1.15]^3``.
    """
    sphere = Sphere((0.0, 0.0, 0.0), 1.0)
    rim = math.sin(math.radians(6.0))
    cand = _fibonacci_sphere(40_000)
    cand = cand[np.all(cand >= rim, axis=1)]
    spec = spread_points(cand, 24, start=np.ones(3) / math.sqrt(3))
    patch = tuple(Halfspace(np.zeros(3), e) for e in np.eye(3))
    return scene_from_points(
        sphere, spec, light=DirectionalLight(np.ones(3)), points=np.eye(3),
        domain=([-0.1] * 3, [1.15] * 3), distance=3.0, patch=patch, name="octant", euler=1,
        mesh_options={"subdivisions": 5}, noise=noise, outliers=outliers, seed=seed,
    )


def car_window(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A gently curved car window (look-alike of the paper's real experiment).

    A patch of a cylinder of radius 2 with a horizontal axis along x, 1.0 wide (x) and 0.6
    high (arc), its centre at the origin with normal tilted 30 degrees toward -y; 38 highlights
    of a directional sun ``normalize(0.3, -0.6, 1)``, each seen by its own camera at distance
    3; two point constraints at diagonal corners; domain: the patch's box grown by 0.15.
    """
    radius = 2.0
    tilt = math.radians(30.0)
    n0 = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    cyl = Cylinder(-radius * n0, (1.0, 0.0, 0.0), radius, reference=n0,
                   extent=(-0.5, 0.5), angles=(-0.15, 0.15))
    half_angle = 0.3 / radius
    # Angles grow from n0 toward axis x n0; bound them with planes through the axis.
    patch = (
        Halfspace((-0.5, 0, 0), (1, 0, 0)),
        Halfspace((0.5, 0, 0), (-1, 0, 0)),
        Halfspace(cyl.point, -np.sin(-half_angle) * cyl.e1 + np.cos(-half_angle) * cyl.e2),
        Halfspace(cyl.point, np.sin(half_angle) * cyl.e1 - np.cos(half_angle) * cyl.e2),
    )
    a, h = np.meshgrid(np.linspace(-0.9, 0.9, 61) * half_angle, np.linspace(-0.45, 0.45, 91))
    spec = spread_points(cyl.at(a.ravel(), h.ravel()), 38, start=cyl.at(0.0, 0.0))
    corners = cyl.at(np.array([-half_angle, half_angle]), np.array([-0.5, 0.5]))
    box = np.concatenate([corners, cyl.at(np.array([-half_angle, half_angle]),
                                          np.array([0.5, -0.5])), cyl.at(0.0, 0.0)[None]])
    domain = (box.min(axis=0) - 0.15, box.max(axis=0) + 0.15)
    return scene_from_points(
        cyl, spec, light=DirectionalLight((0.3, -0.6, 1.0)), points=corners, domain=domain,
        distance=3.0, patch=patch, name="car-window", euler=1, mesh_options={"sections": 64},
        noise=noise, outliers=outliers, seed=seed,
    )


def wine_bottle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A wine bottle lit by the camera flash (look-alike of the paper's real experiment).

    Cylinder of radius 0.04 (metres) with a vertical axis through the origin; the patch of
    glass between the labels spans +-45 degrees around +y and heights 0.11 to 0.19. Eleven
    views along a rising arc at 0.45 from the axis (azimuth -35 to +35 degrees, height 0.12 to
    0.18), each looking at ``(0, 0, 0.15)``; the highlight is searched where the flash mirrors
    back into each camera. Four point constraints at the label corners (+-40 degrees, heights
    0.115 and 0.185); domain: the patch's box grown by 0.01.
    """
    radius = 0.04
    cyl = Cylinder((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), radius, reference=(0.0, 1.0, 0.0),
                   extent=(0.11, 0.19), angles=(-math.pi / 4, math.pi / 4))
    half = math.pi / 4
    patch = (
        Halfspace((0, 0, 0.11), (0, 0, 1)),
        Halfspace((0, 0, 0.19), (0, 0, -1)),
        Halfspace(cyl.point, -np.sin(-half) * cyl.e1 + np.cos(-half) * cyl.e2),
        Halfspace(cyl.point, np.sin(half) * cyl.e1 - np.cos(half) * cyl.e2),
    )
    views = 11
    az = np.radians(np.linspace(-35.0, 35.0, views))
    height = np.linspace(0.12, 0.18, views)
    dist = 0.45
    centres = cyl.point + (dist * (np.cos(az)[:, None] * cyl.e1 + np.sin(az)[:, None] * cyl.e2)
                           + height[:, None] * cyl.axis)
    label = math.radians(40.0)
    pts = cyl.at(np.array([-label, label, label, -label]), np.array([0.115, 0.115, 0.185, 0.185]))
    box = cyl.mesh(sections=32).vertices
    domain = (box.min(axis=0) - 0.01, box.max(axis=0) + 0.01)
    return scene_from_path(
        cyl, centres, light=CameraLight(), look_at_points=(0.0, 0.0, 0.15), points=pts,
        domain=domain, patch=patch, name="wine-bottle", euler=1, mesh_options={"sections": 96},
        noise=noise, outliers=outliers, seed=seed,
    )


def ellipsoid_cap(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                  ) -> SyntheticScene:
    """The top cap of an ellipsoid under a point light.

    Ellipsoid at the origin with radii ``(1, 0.7, 0.5)``, cap ``z >= 0.25``; point light at
    ``(0.6, -0.4, 3)``; 20 highlights spread over ``z >= 0.3``, cameras at distance 2.5; four
    point constraints on the rim of the cap (``z = 0.25``); domain
    ``[-0.95, 0.95] x [-0.7, 0.7] x [0.1, 0.62]``.
    """
    ell = Ellipsoid((0.0, 0.0, 0.0), (1.0, 0.7, 0.5))
    verts = np.asarray(ell.mesh(subdivisions=6).vertices)
    spec = spread_points(verts[verts[:, 2] >= 0.3], 20, start=(0.0, 0.0, 0.5))
    rim = math.sqrt(1 - (0.25 / 0.5) ** 2)
    pts = np.array([[rim, 0, 0.25], [0, 0.7 * rim, 0.25], [-rim, 0, 0.25], [0, -0.7 * rim, 0.25]])
    return scene_from_points(
        ell, spec, light=PointLight((0.6, -0.4, 3.0)), points=pts,
        domain=([-0.95, -0.7, 0.1], [0.95, 0.7, 0.62]), distance=2.5,
        patch=(Halfspace((0, 0, 0.25), (0, 0, 1)),), name="ellipsoid-cap", euler=1,
        mesh_options={"subdivisions": 5}, noise=noise, outliers=outliers, seed=seed,
    )


def paraboloid(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A dome ``z = 0.3 - 0.6 x^2 - 0.4 y^2`` over ``[-0.5, 0.5]^2``.

    Directional light ``normalize(0.2, -0.1, 1)``; 25 highlights spread over
    ``[-0.45, 0.45]^2``, cameras at distance 2.5; the four region corners as point constraints;
    domain ``[-0.6, 0.6]^2 x [-0.2, 0.45]``.
    """
    surf = Paraboloid((0.0, 0.0, 0.3), -0.6, -0.4, region=(-0.5, 0.5, -0.5, 0.5))
    g = np.linspace(-0.45, 0.45, 61)
    xy = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    spec = spread_points(surf.lift(xy), 25, start=(0.0, 0.0, 0.3))
    return scene_from_points(
        surf, spec, light=DirectionalLight((0.2, -0.1, 1.0)), points=surf.corners(),
        domain=([-0.6, -0.6, -0.2], [0.6, 0.6, 0.45]), distance=2.5, name="paraboloid", euler=1,
        mesh_options={"resolution": 96}, noise=noise, outliers=outliers, seed=seed,
    )


def saddle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A saddle ``z = 0.4 (x^2 - y^2)`` over ``[-0.5, 0.5]^2``.

    Directional light ``normalize(-0.2, 0.3, 1)``; 30 highlights spread over
    ``[-0.45, 0.45]^2``, cameras at distance 2.5; point constraints at the four region corners
    and the saddle point; domain ``[-0.6, 0.6]^2 x [-0.25, 0.25]``.
    """
    surf = Saddle((0.0, 0.0, 0.0), 0.4, region=(-0.5, 0.5, -0.5, 0.5))
    g = np.linspace(-0.45, 0.45, 61)
    xy = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    spec = spread_points(surf.lift(xy), 30, start=(0.0, 0.0, 0.0))
    pts = np.concatenate([surf.corners(), [[0.0, 0.0, 0.0]]])
    return scene_from_points(
        surf, spec, light=DirectionalLight((-0.2, 0.3, 1.0)), points=pts,
        domain=([-0.6, -0.6, -0.25], [0.6, 0.6, 0.25]), distance=2.5, name="saddle", euler=1,
        mesh_options={"resolution": 96}, noise=noise, outliers=outliers, seed=seed,
    )


# --------------------------------------------------------------------------------------------
# Scenes of every shape class, their geometry varied by the seed
# --------------------------------------------------------------------------------------------

FREEFORM_HIGHLIGHTS = 60
"""Default number of highlights of the ``freeform`` scene."""

DOMAIN_MARGIN = 0.12
"""Margin of the domain around a closed object, as a fraction of its largest extent."""


def _shape_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of a scene's geometry: its own stream, apart from the noise's."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _around(count: int, rng: np.random.Generator, *, jitter: float = 0.25) -> np.ndarray:
    """``count`` unit directions all around (both hemispheres), rotated and jittered."""
    d = _fibonacci_sphere(count) @ _random_rotation(rng).T
    d += jitter / math.sqrt(count) * rng.standard_normal(d.shape)
    return _normalize(d)


def _margin_box(vertices: np.ndarray, margin: float = DOMAIN_MARGIN
                ) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    pad = margin * float(np.max(hi - lo))
    return lo - pad, hi + pad


def _pick_points(candidates: np.ndarray, surface: Surface, count: int,
                 rng: np.random.Generator) -> np.ndarray:
    """``count`` spread surface points among ``candidates``, which ones chosen by ``rng``."""
    cand = _points(candidates)
    cand = cand[rng.choice(len(cand), size=min(len(cand), 400), replace=False)]
    start = cand[int(rng.integers(len(cand)))]
    return surface.closest_point(spread_points(cand, count, start=start))


def _seen(surface: Surface, x: np.ndarray, light: LightModel, distance: float,
          *, min_cos: float = 0.05) -> np.ndarray:
    """Whether a camera placed by :func:`place_camera` at ``distance`` sees each point ``x``."""
    n = surface.normal(x)
    if isinstance(light, CameraLight):
        v, ok = n, np.ones(len(x), dtype=bool)
    else:
        L = light.towards(x)
        ok = _dot(n, L) >= min_cos
        v = _normalize(reflect(n, L))
    c = x + distance * v
    ok &= surface.implicit(c) > 0
    d = x - c
    t = surface.intersect(c, d / distance, t_min=1e-9 * distance)
    return ok & np.isfinite(t) & (np.abs(t - distance) <= 1e-7 * distance)


def _points_scene(surface: Surface, candidates: np.ndarray, count: int, *, light: LightModel,
                  distance: float, rng: np.random.Generator, **options: Any) -> SyntheticScene:
    """:func:`scene_from_points` with ``count`` well-spread candidates that can be seen."""
    order = spread_points(candidates, min(len(candidates), 2 * count + 20),
                          start=candidates[int(rng.integers(len(candidates)))])
    good = order[_seen(surface, surface.closest_point(order), light, distance)]
    if len(good) < count:
        raise SceneError(f"highlights: only {len(good)} of the {count} asked can be seen")
    return scene_from_points(surface, good[:count], light=light, distance=distance,
                             layout_seed=int(rng.integers(2**31)), **options)


def sphere_around(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                  ) -> SyntheticScene:
    """A whole sphere seen all around by 28 flash cameras (one highlight each), 6 points.

    Radius 0.9-1.1 and centre within 0.1 of the origin (by seed); cameras on jittered
    directions covering both hemispheres at 3-3.4 radii from the centre; domain: the sphere's
    box grown by 12% of its diameter on each side. Outliers are false highlights on the
    sphere.
    """
    rng = _shape_rng(seed, "sphere-around")
    radius = float(rng.uniform(0.9, 1.1))
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Sphere(centre, radius)
    mesh = surf.mesh(subdivisions=5)
    centres = centre + radius * rng.uniform(3.0, 3.4) * _around(28, rng)
    return scene_from_path(
        surf, centres, light=CameraLight(), look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 6, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, name="sphere-around", mesh_options={"subdivisions": 5},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface", closed=True,
        euler=2,
    )


def _lamps(dirs: np.ndarray, rng: np.random.Generator) -> list[DirectionalLight]:
    """One directional lamp per camera direction, 25-40 degrees off it, at a random azimuth."""
    lights = []
    for d in dirs:
        t1, t2 = _tangent_basis(d)
        a = rng.uniform(0, 2 * math.pi)
        tilt = math.radians(rng.uniform(25.0, 40.0))
        lights.append(DirectionalLight(math.cos(tilt) * d + math.sin(tilt)
                                       * (math.cos(a) * t1 + math.sin(a) * t2)))
    return lights


def ellipsoid_around(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                     ) -> SyntheticScene:
    """A whole ellipsoid (axes about 1, 0.82, 0.67) seen all around, one lamp per camera.

    28 cameras on jittered directions all around at 3.2 from the centre; each carries its own
    directional light, 25-40 degrees off its viewing direction, and sees one highlight. Six
    points; domain: the box grown by 12% of the longest axis. The seed varies the radii (by
    up to 6%), the centre, the cameras and the lights.
    """
    rng = _shape_rng(seed, "ellipsoid-around")
    radii = np.array([1.0, 0.82, 0.67]) * rng.uniform(0.94, 1.06, 3)
    return _ellipsoid_under_lamps("ellipsoid-around", radii, rng, noise=noise,
                                  outliers=outliers, seed=seed)


def _ellipsoid_under_lamps(name: str, radii: np.ndarray, rng: np.random.Generator, *,
                           noise: float, outliers: float, seed: int) -> SyntheticScene:
    """An ellipsoid of ``radii`` about a centre within 0.1 of the origin, seen all around.

    28 cameras at 3.2 from the centre, each with its own lamp (:func:`_lamps`), six points;
    domain: the box grown by 12% of the longest axis. ``rng`` draws the centre, the cameras,
    the lamps and the points, in that order.
    """
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Ellipsoid(centre, radii)
    mesh = surf.mesh(subdivisions=5)
    dirs = _around(28, rng)
    return scene_from_path(
        surf, centre + 3.2 * dirs, light=_lamps(dirs, rng), look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 6, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, name=name, mesh_options={"subdivisions": 5},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface", closed=True,
        euler=2,
    )


def pebble(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A flat ellipsoid (a pebble or a lens: axes about 1, 0.9, 0.35) seen all around.

    As ``ellipsoid-around`` (28 cameras at 3.2 from the centre, each with its own directional
    lamp 25-40 degrees off its viewing direction, six points, the box grown by 12% of the
    longest axis), but about three times longer than thick: most points lie on the flat
    faces, well inside the rim. The seed varies the radii (the short one from 0.3 to 0.4),
    which axis each lies along, the centre, the cameras and the lights.
    """
    rng = _shape_rng(seed, "pebble")
    radii = np.array([1.0, rng.uniform(0.85, 0.95), rng.uniform(0.3, 0.4)])[rng.permutation(3)]
    return _ellipsoid_under_lamps("pebble", radii, rng, noise=noise, outliers=outliers,
                                  seed=seed)


def blob(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A closed free-form object (:class:`~.surfaces.Blob`) seen all around by flash cameras.

    A sphere of radius 0.9-1.1 raised by three bumps of 0.15-0.3 radii, each about 0.45-0.65
    radians wide, in random directions (by seed): no quadric, torus or surface of revolution.
    40 cameras on jittered directions all around at 3.4 radii from the centre; each keeps up to
    2 visible highlights. Six points; domain: the box grown by 12% of its largest side.
    """
    rng = _shape_rng(seed, "blob")
    radius = float(rng.uniform(0.9, 1.1))
    centre = rng.uniform(-0.1, 0.1, 3)
    bumps = [(float(rng.uniform(0.15, 0.3)), _normalize(rng.standard_normal(3)),
              float(rng.uniform(0.45, 0.65))) for _ in range(3)]
    surf = Blob(centre, radius, bumps)
    mesh = surf.mesh(subdivisions=5)
    return scene_from_path(
        surf, centre + 3.4 * radius * _around(40, rng), light=CameraLight(),
        look_at_points=centre, points=_pick_points(mesh.vertices, surf, 6, rng),
        domain=_margin_box(mesh.vertices), candidates=mesh.vertices, name="blob",
        mesh_options={"subdivisions": 5}, noise=noise, outliers=outliers, seed=seed,
        per_view=2, false_highlights="surface", closed=True, euler=2,
    )


def torus(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A ring torus (tube about 0.35 of the major radius) seen all around by flash cameras.

    Major radius 0.95-1.05, tube 0.33-0.37 of it, axis tilted up to about 10 degrees from
    ``z`` (by seed). 30 cameras on jittered directions all around at 4 from the centre plus
    one above and one below looking through the hole; each keeps up to 3 visible highlights
    (a torus shows several). Eight points; domain: the box grown by 12% of the diameter.
    """
    return _torus(noise=noise, outliers=outliers, seed=seed, lighting="flash")


def torus_lamps(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                ) -> SyntheticScene:
    """The ``torus`` scene's shape and cameras, each camera with its own directional lamp.

    Each lamp is 25-40 degrees off its camera's viewing direction (as in
    ``ellipsoid-around``), so a ray is no longer a normal line of the surface.
    """
    return _torus(noise=noise, outliers=outliers, seed=seed, lighting="lamps")


TORUS_POINT_VIEW_DEG = 75.0
"""Under a point lamp a torus shows highlights seen almost edge on (up to 88 degrees from the
normal), where a detector finds no glint: ``torus-point`` keeps those seen within this."""


def torus_point(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0
                ) -> SyntheticScene:
    """The ``torus`` scene's shape and cameras under one point lamp 3 from its centre.

    The lamp stands 20-40 degrees off the axis (by seed), above the ring; the normal the
    reflection law asks moves with the point where a ray meets the surface. Highlights seen
    more than 75 degrees off their normal are left out.
    """
    return _torus(noise=noise, outliers=outliers, seed=seed, lighting="point")


def _torus(*, noise: float, outliers: float, seed: int, lighting: str) -> SyntheticScene:
    rng = _shape_rng(seed, "torus")
    major = float(rng.uniform(0.95, 1.05))
    minor = major * float(rng.uniform(0.33, 0.37))
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.1 * rng.standard_normal(3))
    centre = rng.uniform(-0.1, 0.1, 3)
    surf = Torus(centre, axis, major, minor)
    mesh = surf.mesh()
    dirs = _around(30, rng)
    t1, t2 = _tangent_basis(axis)
    poles = [_normalize(s * axis + 0.12 * t1 + 0.05 * rng.standard_normal(3)) for s in (1, -1)]
    dirs = np.concatenate([dirs, poles])
    name = "torus" if lighting == "flash" else f"torus-{lighting}"
    if lighting == "lamps":
        light = _lamps(dirs, _shape_rng(seed, name))
    elif lighting == "point":
        lamp_rng = _shape_rng(seed, name)
        tilt, az = math.radians(lamp_rng.uniform(20.0, 40.0)), lamp_rng.uniform(0, 2 * math.pi)
        towards = math.cos(tilt) * axis + math.sin(tilt) * (math.cos(az) * t1 + math.sin(az) * t2)
        light = PointLight(centre + 3.0 * towards)
    else:
        light = CameraLight()
    return scene_from_path(
        surf, centre + 4.0 * dirs, light=light, look_at_points=centre,
        points=_pick_points(mesh.vertices, surf, 8, rng), domain=_margin_box(mesh.vertices),
        candidates=mesh.vertices, intrinsics=Intrinsics(focal=560.0), up=axis,
        name=name, noise=noise, outliers=outliers, seed=seed,
        per_view=3, false_highlights="surface", closed=True, euler=0,
        max_view_deg=TORUS_POINT_VIEW_DEG if lighting == "point" else None,
    )


BOTTLE_RINGS = {1: ((0.7, 0.3, 20),), 2: ((0.0, 0.0, 14), (1.05, 0.45, 14))}
"""The bottle's camera rings by count: (height, height aimed at, cameras) along its axis."""


def bottle(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
           rings: int = 2, shoulder: float = 1.0, body: float = 1.0) -> SyntheticScene:
    """A bottle (body, shoulder, neck; a surface of revolution) seen by rings of flashes.

    Body radius about 0.35, neck about 0.13, shoulder about 0.35 above the base point, axis
    near ``z`` (all varied by seed). ``rings=2``: 14 cameras on a ring at the body's height and
    14 above the shoulder; ``rings=1``: 20 on one ring at height 0.7, looking down at 0.3
    (a half-space holds them all). 1.6 from the axis; each keeps up to 2 highlights. Six
    points. The domain holds the bottle's width with a 12% margin and cuts its body below
    (height -0.45) and its neck above (height 0.85), so the truth is an open tube (Euler
    number 0). ``shoulder`` scales the shoulder's width (about 0.09; 0.5: half as wide, a
    sharper shoulder), ``body`` the body's radius (1.3: about 0.45, a deeper shoulder).

    Raises:
        SceneError: If ``rings`` is not 1 or 2, ``shoulder`` not a number from 0.25 to 3,
            or ``body`` not a number from 0.5 to 1.6.
    """
    return _bottle(noise=noise, outliers=outliers, seed=seed, lamps=False, rings=rings,
                   shoulder=shoulder, body=body)


def bottle_lamps(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
                 rings: int = 2, shoulder: float = 1.0, body: float = 1.0) -> SyntheticScene:
    """The ``bottle`` scene's shape and cameras, each camera with its own directional lamp.

    Each lamp is 25-40 degrees off its camera's viewing direction (as in
    ``ellipsoid-around``), so a ray is no longer a normal line of the surface.
    """
    return _bottle(noise=noise, outliers=outliers, seed=seed, lamps=True, rings=rings,
                   shoulder=shoulder, body=body)


def _bottle(*, noise: float, outliers: float, seed: int, lamps: bool,
            rings: int, shoulder: float, body: float) -> SyntheticScene:
    if isinstance(rings, bool) or rings not in BOTTLE_RINGS:
        raise SceneError(f"rings: expected one of {sorted(BOTTLE_RINGS)}, got {rings!r}")
    if (isinstance(shoulder, bool) or not isinstance(shoulder, int | float)
            or not 0.25 <= shoulder <= 3.0):
        raise SceneError(f"shoulder: must be a number from 0.25 to 3 (a scale of the "
                         f"shoulder's width), got {shoulder!r}")
    if (isinstance(body, bool) or not isinstance(body, int | float)
            or not 0.5 <= body <= 1.6):
        raise SceneError(f"body: must be a number from 0.5 to 1.6 (a scale of the body's "
                         f"radius), got {body!r}")
    rng = _shape_rng(seed, "bottle")
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.05 * rng.standard_normal(3))
    base = rng.uniform(-0.05, 0.05, 3)
    radius = 0.35 * float(body) * float(rng.uniform(0.93, 1.07))
    surf = Revolution(base, axis, body=radius, neck=0.13 * float(rng.uniform(0.9, 1.1)),
                      shoulder=0.35 + float(rng.uniform(-0.04, 0.04)),
                      width=0.09 * float(shoulder) * float(rng.uniform(0.9, 1.1)))
    # The domain: heights -0.45..0.85 along z, the width with a margin (the axis leans a bit,
    # so the cut is taken along z through the tube's ends).
    lo_z, hi_z = base[2] - 0.45, base[2] + 0.85
    pad = DOMAIN_MARGIN * 2 * radius
    h_lo = (lo_z - base[2]) / axis[2] - 0.2
    h_hi = (hi_z - base[2]) / axis[2] + 0.2
    full = surf.mesh(extent=(h_lo, h_hi))
    patch = (Halfspace((0, 0, lo_z), (0, 0, 1)), Halfspace((0, 0, hi_z), (0, 0, -1)))
    verts = clip_mesh(full, patch).vertices
    lo = np.append(verts.min(axis=0)[:2] - pad, lo_z)
    hi = np.append(verts.max(axis=0)[:2] + pad, hi_z)
    centres, targets = [], []
    for height, aim, count in BOTTLE_RINGS[rings]:
        az = np.linspace(0, 2 * math.pi, count, endpoint=False) + rng.uniform(0, 2 * math.pi)
        az = az + rng.uniform(-0.1, 0.1, len(az))
        ring = 1.6 * (np.cos(az)[:, None] * surf.e1 + np.sin(az)[:, None] * surf.e2)
        centres.append(base + ring + (height + rng.uniform(-0.05, 0.05, (len(az), 1))) * axis)
        targets.append(np.tile(base + aim * axis, (len(az), 1)))
    centres, targets = np.concatenate(centres), np.concatenate(targets)
    light = (_lamps(_normalize(centres - targets), _shape_rng(seed, "bottle-lamps"))
             if lamps else CameraLight())
    return scene_from_path(
        surf, centres, light=light, look_at_points=targets,
        points=_pick_points(verts[(verts[:, 2] > lo_z + 0.05) & (verts[:, 2] < hi_z - 0.05)],
                            surf, 6, rng), domain=(lo, hi),
        candidates=verts, patch=patch, up=axis, name="bottle-lamps" if lamps else "bottle",
        mesh_options={"extent": (h_lo, h_hi)}, noise=noise, outliers=outliers, seed=seed,
        per_view=2, false_highlights="surface", closed=False, euler=0,
    )


def wrap(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
         span: float | None = None) -> SyntheticScene:
    """A cylinder patch wrapping 200-240 degrees around its axis, seen from its convex side.

    Radius about 0.5, axial length about 0.8, axis near ``z`` (by seed); 36 highlights spread
    over the patch (inset from its edges by 5% of its span), each seen by its own flash camera
    2 from the point along the normal: a ring of cameras around the axis. Five points;
    domain: the patch's box grown by 12% of its size. An open patch (Euler number 1).
    ``span`` (degrees, 90 to 330) replaces the seeded span.

    Raises:
        SceneError: If ``span`` is not a number from 90 to 330.
    """
    rng = _shape_rng(seed, "wrap")
    radius = 0.5 * float(rng.uniform(0.93, 1.07))
    seeded = float(rng.uniform(200.0, 240.0))
    if span is not None and (isinstance(span, bool) or not isinstance(span, int | float)
                             or not 90.0 <= span <= 330.0):
        raise SceneError(f"span: must be a number of degrees from 90 to 330, got {span!r}")
    span = math.radians(seeded if span is None else float(span))
    start = float(rng.uniform(0, 2 * math.pi))
    half = 0.4 * float(rng.uniform(0.9, 1.1))
    axis = _normalize(np.array([0.0, 0.0, 1.0]) + 0.08 * rng.standard_normal(3))
    cyl = Cylinder(rng.uniform(-0.05, 0.05, 3), axis, radius, extent=(-half, half),
                   angles=(start, start + span))
    a, h = np.meshgrid(start + span * np.linspace(0.05, 0.95, 61),
                       np.linspace(-0.85, 0.85, 31) * half)
    cand = cyl.at(a.ravel(), h.ravel())
    mesh = cyl.mesh(sections=128)
    corners = cyl.at(start + span * np.array([0.02, 0.98, 0.98, 0.02, 0.5]),
                     half * np.array([-0.95, -0.95, 0.95, 0.95, 0.0]))
    return _points_scene(
        cyl, cand, 36, light=CameraLight(), distance=2.0, rng=rng, points=corners,
        domain=_margin_box(mesh.vertices), up=axis, name="wrap",
        mesh_options={"sections": 128}, noise=noise, outliers=outliers, seed=seed,
        false_highlights="surface", closed=False, euler=1,
    )


def _freeform_surface(rng: np.random.Generator) -> FreeformHeightField:
    waves = []
    for _ in range(3):
        k = 2 * math.pi * float(rng.uniform(0.7, 1.4))
        ang = float(rng.uniform(0, math.pi))
        waves.append((float(rng.uniform(0.03, 0.05)), k * math.cos(ang), k * math.sin(ang),
                      float(rng.uniform(0, 2 * math.pi))))
    bump = (float(rng.uniform(0.1, 0.14)), *rng.uniform(-0.2, 0.2, 2),
            float(rng.uniform(0.11, 0.15)))
    return FreeformHeightField(waves=waves, bumps=[bump], region=(-0.5, 0.5, -0.5, 0.5))


def freeform(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
             highlights: int = FREEFORM_HIGHLIGHTS) -> SyntheticScene:
    """A free-form height-field patch (three sine waves and a Gaussian bump), seen from above.

    Over ``[-0.5, 0.5]^2``: waves of amplitude 0.03-0.05 and wavelength 0.7-1.4, a bump of
    height 0.10-0.14 (all by seed); ``highlights`` (default 60) highlights spread over the
    patch, each seen by its own camera 2.5 away under a directional light near ``+z``. Five
    points (four near the corners, one inside); domain: the patch grown by 0.12 each side.

    Raises:
        SceneError: If ``highlights`` is not an integer from 4 to 400.
    """
    if isinstance(highlights, bool) or not isinstance(highlights, int | np.integer) or not (
            4 <= highlights <= 400):
        raise SceneError(f"highlights: must be an integer from 4 to 400, got {highlights!r}")
    rng = _shape_rng(seed, "freeform")
    surf = _freeform_surface(rng)
    light = DirectionalLight(np.array([0.0, 0.0, 1.0]) + 0.25 * rng.standard_normal(3) * [1, 1, 0])
    g = np.linspace(-0.46, 0.46, 93)
    cand = surf.lift(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))
    corners = np.array([[-0.44, -0.44], [0.44, -0.44], [0.44, 0.44], [-0.44, 0.44]])
    corners = corners + rng.uniform(-0.03, 0.03, corners.shape)
    pts = surf.lift(np.concatenate([corners, rng.uniform(-0.25, 0.25, (1, 2))]))
    return _points_scene(
        surf, cand, int(highlights), light=light, distance=2.5, rng=rng, points=pts,
        domain=_sheet_domain(surf), name="freeform", mesh_options={"resolution": 128},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface",
        closed=False, euler=1,
    )


def _sheet_domain(surf: FreeformHeightField, margin: float = DOMAIN_MARGIN
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A box that the sheet cuts through: the region grown by ``margin``, heights padded."""
    x0, x1, y0, y1 = surf.region
    g = np.stack(np.meshgrid(np.linspace(x0 - margin, x1 + margin, 97),
                             np.linspace(y0 - margin, y1 + margin, 97), indexing="ij"), -1)
    hz = surf.height(g.reshape(-1, 2))
    return (np.array([x0 - margin, y0 - margin, hz.min() - margin]),
            np.array([x1 + margin, y1 + margin, hz.max() + margin]))


def point_light(*, noise: float = 0.0, outliers: float = 0.0, seed: int = 0) -> SyntheticScene:
    """A bumpy dome lit by a point lamp 2 above it: 30 highlights, 5 points.

    Dome ``0.3 - 0.5 x^2 - 0.4 y^2`` (coefficients varied by up to 15%) with two Gaussian bumps
    of height 0.04-0.06 over ``[-0.5, 0.5]^2``; the lamp within 0.3 of the axis at height 2;
    each highlight seen by its own camera 2.5 away. Domain: the patch grown by 0.12.
    """
    rng = _shape_rng(seed, "point-light")
    bumps = [(float(rng.uniform(0.04, 0.06)), *rng.uniform(-0.3, 0.3, 2),
              float(rng.uniform(0.09, 0.13))) for _ in range(2)]
    surf = FreeformHeightField(z0=0.3, dome=np.array([0.5, 0.4]) * rng.uniform(0.85, 1.15, 2),
                               bumps=bumps, region=(-0.5, 0.5, -0.5, 0.5))
    lamp = PointLight(np.append(rng.uniform(-0.3, 0.3, 2), 2.0))
    g = np.linspace(-0.46, 0.46, 71)
    cand = surf.lift(np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2))
    pts = surf.lift(np.array([[-0.45, -0.45], [0.45, -0.45], [0.45, 0.45], [-0.45, 0.45],
                              [0.0, 0.0]]) + rng.uniform(-0.03, 0.03, (5, 2)))
    return _points_scene(
        surf, cand, 30, light=lamp, distance=2.5, rng=rng, points=pts,
        domain=_sheet_domain(surf), name="point-light", mesh_options={"resolution": 128},
        noise=noise, outliers=outliers, seed=seed, false_highlights="surface",
        closed=False, euler=1,
    )


SCENES: dict[str, Callable[..., SyntheticScene]] = {
    "octant": octant,
    "car-window": car_window,
    "wine-bottle": wine_bottle,
    "ellipsoid-cap": ellipsoid_cap,
    "paraboloid": paraboloid,
    "saddle": saddle,
    "sphere-around": sphere_around,
    "ellipsoid-around": ellipsoid_around,
    "pebble": pebble,
    "torus": torus,
    "torus-lamps": torus_lamps,
    "torus-point": torus_point,
    "blob": blob,
    "bottle": bottle,
    "bottle-lamps": bottle_lamps,
    "wrap": wrap,
    "freeform": freeform,
    "point-light": point_light,
}


def scene_names() -> list[str]:
    """Names of the built-in scenes."""
    return list(SCENES)


NOISE_RESOLUTION = DEFAULTS["resolution"]
"""The resolution whose voxel is the unit of ``point_noise``: the reconstruction's default."""


def make_scene(name: str, *, noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
               point_noise: float = 0.0, **options: Any) -> SyntheticScene:
    """A built-in scene by name (see :data:`SCENES`).

    Args:
        name: One of :func:`scene_names`.
        noise: Pixel noise standard deviation in pixels.
        outliers: Fraction of specularities replaced by false ones.
        seed: Seed of the noise and outliers; for the scenes of every shape class
            (``sphere-around`` to ``point-light``) also of the geometry (sizes, bumps, camera
            jitter, which points are chosen). The paper's scenes keep a fixed geometry.
        **options: Options only some scenes take (``freeform``: ``highlights``; ``wrap``:
            ``span``; ``bottle`` and ``bottle-lamps``: ``rings``, ``shoulder``, ``body``).
        point_noise: Standard deviation of Gaussian noise added to each coordinate of the
            point constraints (:func:`~warpspec.synthetic.scenes.jitter_points`), in voxels
            of the default grid: the domain's longest side over :data:`NOISE_RESOLUTION`.

    Raises:
        SceneError: If the name is unknown, a scene does not take an option, or the settings
            are out of range.
    """
    if name not in SCENES:
        raise SceneError(f"scene: unknown name {name!r}, expected one of {scene_names()}")
    make = SCENES[name]
    params = inspect.signature(make).parameters
    for key in options:
        if key not in params:
            raise SceneError(f"{key}: scene {name!r} takes no such option")
    if not (np.isfinite(point_noise) and point_noise >= 0):
        raise SceneError(f"point_noise: must be a non-negative number of voxels, got "
                         f"{point_noise!r}")
    synthetic = make(noise=noise, outliers=outliers, seed=seed, **options)
    if point_noise == 0:
        return synthetic
    lo, hi = synthetic.domain
    voxel = float(np.max(hi - lo)) / NOISE_RESOLUTION
    return jitter_points(synthetic, sigma=point_noise * voxel, seed=seed)

