"""Synthetic scenes with ground truth: surfaces, cameras that see chosen highlights, noise.

A synthetic scene is a known surface, a light, and cameras placed so that each sees a specular
highlight at a known surface point: the camera sits on the direction into which the surface
mirrors the light. The scene is written in the version-1 scene format (docs/DESIGN.md section
10) and kept together with its ground truth (specular points, normals, a truth mesh).

Geometry follows docs/DESIGN.md section 2 (:mod:`warpspec.geometry`: camera centres, pixel rays,
the reflection law, the light models). Cameras follow the usual computer-vision frame (x right,
y down, z forward); pixel ``(u, v)`` lies in the image when ``0 <= u <= width - 1`` and
``0 <= v <= height - 1``.

Surfaces implement a small protocol (:class:`Surface`): ``implicit`` (negative inside, positive
on the camera side), ``signed_distance``, ``normal`` (outward), ``closest_point``,
``intersect`` (first hit along rays), ``chart`` (a smooth local parametrisation), ``sample``
and ``mesh`` (a truth mesh). Open surfaces (planes, height fields) face ``+z`` or their given
normal; the cameras must look from that side.

Built-in scenes (:func:`make_scene`) reproduce the paper's experiments with look-alike data:
``octant``, ``car-window``, ``wine-bottle``, plus ``ellipsoid-cap``, ``paraboloid`` and
``saddle``. Their geometry is fixed; ``seed`` drives only the pixel noise and the outliers.

A second set covers every shape class, its geometry varied a little by ``seed`` (sizes, axis
ratios, bump positions, camera jitter, which points are chosen): closed objects seen all around
(``sphere-around``, ``ellipsoid-around`` with a lamp per camera and ``pebble``, a flat one,
``torus`` by flash and
``torus-lamps`` with a lamp per camera, ``torus-point`` under one point lamp, and ``blob``, a
sphere raised by bumps that no closed-form shape fits), a ``bottle`` open at the domain's ends
(by flash, and ``bottle-lamps`` with a lamp per camera), a ``wrap`` patch spanning more than
180 degrees, a ``freeform`` height field (``highlights`` chooses how many) and a
``point-light`` dome. Their outliers are false highlights on the object (a pixel whose ray meets the
truth where the reflection law's normal is wrong by 15 degrees or more), and their truth
records whether it is closed and its Euler number.

The package: :mod:`.surfaces` (the protocol and the shapes), :mod:`.cameras` (intrinsics, camera
placement, patches, highlight search), :mod:`.scenes` (:class:`SyntheticScene`, building scenes
from points or a path, noise and outliers) and :mod:`.catalogue` (the built-in scenes by name).
"""

from ..geometry import (
    CameraLight,
    DirectionalLight,
    LightModel,
    PointLight,
    as_light,
    camera_centre,
    pixel_rays,
    project,
    reflect,
)
from .cameras import (
    Halfspace,
    Intrinsics,
    clip_mesh,
    find_highlight,
    find_highlights,
    look_at,
    place_camera,
    spread_points,
)
from .catalogue import (
    DOMAIN_MARGIN,
    FREEFORM_HIGHLIGHTS,
    SCENES,
    car_window,
    ellipsoid_cap,
    make_scene,
    octant,
    paraboloid,
    saddle,
    scene_names,
    wine_bottle,
)
from .scenes import (
    SyntheticScene,
    corrupt_pixels,
    jitter_points,
    scene_from_path,
    scene_from_points,
)
from .surfaces import (
    Blob,
    Cylinder,
    Ellipsoid,
    FreeformHeightField,
    MeshSurface,
    Paraboloid,
    Plane,
    QuadraticHeightField,
    Revolution,
    Saddle,
    Sphere,
    Surface,
    Torus,
)

__all__ = [
    "Blob",
    "CameraLight",
    "Cylinder",
    "DOMAIN_MARGIN",
    "DirectionalLight",
    "Ellipsoid",
    "FREEFORM_HIGHLIGHTS",
    "FreeformHeightField",
    "Halfspace",
    "Intrinsics",
    "LightModel",
    "MeshSurface",
    "Paraboloid",
    "Plane",
    "PointLight",
    "QuadraticHeightField",
    "Revolution",
    "SCENES",
    "Saddle",
    "Sphere",
    "Surface",
    "SyntheticScene",
    "Torus",
    "as_light",
    "camera_centre",
    "car_window",
    "clip_mesh",
    "corrupt_pixels",
    "ellipsoid_cap",
    "find_highlight",
    "find_highlights",
    "jitter_points",
    "look_at",
    "make_scene",
    "octant",
    "paraboloid",
    "pixel_rays",
    "place_camera",
    "project",
    "reflect",
    "saddle",
    "scene_from_path",
    "scene_from_points",
    "scene_names",
    "spread_points",
    "wine_bottle",
]
