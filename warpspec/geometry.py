"""The geometry every part of warpspec shares (docs/DESIGN.md section 2).

Cameras: ``P = [M | p4]`` (3x4), centre ``c = -M^-1 p4``, the ray of pixel ``q = (u, v, 1)``
has direction ``normalize(sign(det M) M^-1 q)`` from the camera into the scene. The reflection
law: ``N = normalize(L - r)``, ``L`` the unit vector toward the light. The three light models
and their codes (the one definition the Warp kernels take their ``wp.constant`` values from).
Planes: a plane's frame, the best-fit plane of points and the one tolerance that calls points
collinear. Crops: the regions the constraints cover (their 2-D hull on the best-fit plane, their
3-D hull) and the meshes cut to them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .errors import InputError, ReconstructionError, SceneError

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "COLLINEAR_TOL",
    "CameraLight",
    "DirectionalLight",
    "HullRegion",
    "LIGHT_CAMERA",
    "LIGHT_CODES",
    "LIGHT_DIRECTIONAL",
    "LIGHT_KINDS",
    "LIGHT_POINT",
    "LightModel",
    "as_light",
    "best_fit_plane",
    "camera_centre",
    "crop_to_data_hull",
    "crop_to_hull",
    "crop_to_unwrapped_hull",
    "hull_region",
    "pixel_rays",
    "plane_frame",
    "project",
    "reflect",
]

# --------------------------------------------------------------------------------------------
# Light codes

LIGHT_DIRECTIONAL = 0
"""Light code of a directional light (one constant direction ``L``)."""
LIGHT_POINT = 1
"""Light code of a point light (``L = normalize(p - x)``)."""
LIGHT_CAMERA = 2
"""Light code of a flash at the camera centre (``N = -r``)."""

LIGHT_CODES = {"directional": LIGHT_DIRECTIONAL, "point": LIGHT_POINT, "camera": LIGHT_CAMERA}
"""The code of each light type of the scene format."""
LIGHT_KINDS = '"directional", "point" or "camera"'
"""The light types, as error messages list them."""

# --------------------------------------------------------------------------------------------
# Planes

COLLINEAR_TOL = 1e-6
"""Points whose second singular value (about their centroid) is at most this fraction of the
first are collinear: they determine no plane. The scene's check warns about them and the paper's
start then orients its plane by the normals instead, so the two agree."""


def _vec3(value: Any, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SceneError(f"{name}: expected 3 finite numbers, got {value!r}")
    return v


def _unit3(value: Any, name: str) -> np.ndarray:
    v = _vec3(value, name)
    n = float(np.linalg.norm(v))
    if n == 0:
        raise SceneError(f"{name}: must be a non-zero vector, got {value!r}")
    return v / n


def _points(x: Any) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).reshape(-1, 3)


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def angle_deg(cos: np.ndarray) -> np.ndarray:
    """The angle in degrees whose cosine is ``cos``, clipped to ``[-1, 1]`` first."""
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def miss_deg(gradient: np.ndarray, normals: np.ndarray, met: np.ndarray) -> np.ndarray:
    """The angle (degrees) between each unit ``gradient`` and its normal; 180 where not ``met``.

    A ray's miss: how far the surface's normal where the ray meets it is from the normal the
    ray asks, with 180 for a ray that does not meet the surface.
    """
    return np.where(met, angle_deg(_dot(gradient, normals)), 180.0)


def best_fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The least-squares plane of points: their centroid and its principal axes.

    Args:
        points: Points ``(N, 3)``.

    Returns:
        The centroid ``(3,)`` and the rows of ``V^T`` of the centred points' SVD ``(3, 3)``
        (two in-plane axes, then the normal), or ``None`` when there are fewer than three
        points or they are collinear (second singular value at most :data:`COLLINEAR_TOL`
        times the first).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return np.zeros(3), None
    # scaled first, so that coordinates near the float64 limit neither overflow nor vanish
    scale = float(np.max(np.abs(points)))
    scale = scale if 0.0 < scale < math.inf else 1.0
    unit = points / scale
    centroid = unit.mean(axis=0)
    if len(points) < 3:
        return centroid * scale, None
    _, s, vt = np.linalg.svd(unit - centroid, full_matrices=False)
    if not s[1] > COLLINEAR_TOL * max(s[0], 1e-300):
        return centroid * scale, None
    return centroid * scale, vt


def plane_frame(normal: np.ndarray) -> np.ndarray:
    """Two unit axes spanning the plane of ``normal``, and the normal: rows of a 3x3 matrix."""
    n = normal / np.linalg.norm(normal)
    helper = np.eye(3)[np.argmin(np.abs(n))]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(n, u), n])



# --------------------------------------------------------------------------------------------
# Lights


@dataclass(frozen=True, eq=False)
class DirectionalLight:
    """A light at infinity; ``direction`` is the unit vector toward the light (``L``)."""

    code: ClassVar[int] = LIGHT_DIRECTIONAL
    """The light's ``LIGHT_*`` code."""

    direction: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "direction", _unit3(self.direction, "light.direction"))

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the light."""
        return np.tile(self.direction, (len(_points(x)), 1))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "directional", "direction": self.direction.tolist()}


@dataclass(frozen=True, eq=False)
class PointLight:
    """A point light at ``position``: ``L = normalize(position - x)``."""

    code: ClassVar[int] = LIGHT_POINT
    """The light's ``LIGHT_*`` code."""

    position: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec3(self.position, "light.position"))

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the light."""
        return _normalize(self.position - _points(x))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "point", "position": self.position.tolist()}


@dataclass(frozen=True)
class CameraLight:
    """A flash at each camera centre: ``L = normalize(centre - x)``, so ``N = -r``."""

    code: ClassVar[int] = LIGHT_CAMERA
    """The light's ``LIGHT_*`` code."""

    def towards(self, x: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
        """Unit vectors ``(N, 3)`` from the points ``x`` toward the camera ``centre``."""
        if centre is None:
            raise SceneError("light: a camera flash needs the camera centre")
        return _normalize(np.asarray(centre, dtype=np.float64) - _points(x))

    def to_dict(self) -> dict:
        """Scene-file form."""
        return {"type": "camera"}


LightModel = DirectionalLight | PointLight | CameraLight
"""Any of the three light models of docs/DESIGN.md section 2."""


def as_light(light: LightModel | dict) -> LightModel:
    """A light object from itself or from its scene-file dictionary.

    Raises:
        SceneError: If the dictionary is not a valid light.
    """
    if isinstance(light, DirectionalLight | PointLight | CameraLight):
        return light
    if not isinstance(light, dict):
        raise SceneError(f"light: expected a light or a dict, got {light!r}")
    kind = light.get("type")
    if kind == "directional":
        return DirectionalLight(light.get("direction"))
    if kind == "point":
        return PointLight(light.get("position"))
    if kind == "camera":
        return CameraLight()
    raise SceneError(f"light.type: expected 'directional', 'point' or 'camera', got {kind!r}")


# --------------------------------------------------------------------------------------------
# Cameras and the reflection law


def camera_centre(P: np.ndarray) -> np.ndarray:
    """Centre ``c = -M^-1 p4`` of a finite camera ``P = [M | p4]`` (3x4)."""
    P = np.asarray(P, dtype=np.float64)
    return -np.linalg.solve(P[:, :3], P[:, 3])


def pixel_rays(P: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays of pixels: origin at the centre, unit ``normalize(sign(det M) M^-1 q)``.

    Args:
        P: Camera matrix (3x4).
        pixels: Pixels ``(N, 2)``.

    Returns:
        The camera centre ``(3,)`` and the unit directions ``(N, 3)`` into the scene.
    """
    P = np.asarray(P, dtype=np.float64)
    M = P[:, :3]
    q = np.column_stack([np.asarray(pixels, dtype=np.float64).reshape(-1, 2),
                         np.ones(len(np.asarray(pixels).reshape(-1, 2)))])
    d = np.linalg.solve(M, q.T).T * np.sign(np.linalg.det(M))
    return camera_centre(P), _normalize(d)


def project(P: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points.

    Args:
        P: Camera matrix (3x4).
        points: World points ``(N, 3)``.

    Returns:
        Pixels ``(N, 2)`` and depths ``(N,)`` (positive in front of the camera).
    """
    P = np.asarray(P, dtype=np.float64)
    x = _points(points)
    h = x @ P[:, :3].T + P[:, 3]
    M = P[:, :3]
    depth = np.sign(np.linalg.det(M)) * h[:, 2] / np.linalg.norm(M[2])
    return h[:, :2] / h[:, 2:3], depth


def reflect(normal: np.ndarray, light_dir: np.ndarray) -> np.ndarray:
    """Mirror direction ``v = 2 (n.L) n - L`` (rows of ``(N, 3)`` or single vectors)."""
    n = np.asarray(normal, dtype=np.float64)
    L = np.asarray(light_dir, dtype=np.float64)
    return 2 * _dot(n, L)[..., None] * n - L



# --------------------------------------------------------------------------------------------
# Crops: the regions the constraints cover


@dataclass(frozen=True)
class HullRegion:
    """The region covered by a set of constraint points, seen along their best-fit plane.

    A point is inside when its projection onto the plane falls inside the 2D convex hull of
    the projected constraint points, grown by ``margin``.

    Attributes:
        centre: Centroid of the constraint points, shape ``(3,)``.
        axes: Two orthonormal in-plane axes, shape ``(2, 3)``.
        normal: Unit normal of the best-fit plane, shape ``(3,)``.
        hull: Vertices of the 2D convex hull in plane coordinates, counter-clockwise, ``(K, 2)``.
        margin: Distance in world units by which the hull is grown (each edge moved out).
        height: When set, points farther than this from the plane are outside (useful when a
            closed mesh would put its far side in the hull's shadow).
    """

    centre: np.ndarray
    axes: np.ndarray
    normal: np.ndarray
    hull: np.ndarray
    margin: float = 0.0
    height: float | None = None

    def project(self, points: np.ndarray) -> np.ndarray:
        """Plane coordinates ``(N, 2)`` of world points ``(N, 3)``."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return (points - self.centre) @ self.axes.T

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask ``(N,)``: whether each world point projects inside the region."""
        uv = self.project(points)
        inside = np.ones(len(uv), dtype=bool)
        k = len(self.hull)
        scale = max(float(np.abs(self.hull).max()), 1e-300)
        for i in range(k):
            p, q = self.hull[i], self.hull[(i + 1) % k]
            edge = q - p
            length = float(np.hypot(*edge))
            # Signed distance to the edge's line, positive on the inner (left) side.
            s = (edge[0] * (uv[:, 1] - p[1]) - edge[1] * (uv[:, 0] - p[0])) / length
            inside &= s >= -self.margin - 1e-12 * scale
        if self.height is not None:
            off = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.centre) @ self.normal
            inside &= np.abs(off) <= self.height
        return inside


def _convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of 2D points (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.asarray(points, dtype=np.float64))))

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=np.float64).reshape(-1, 2)


def hull_region(
    points: np.ndarray, *, margin: float = 0.0, height: float | None = None
) -> HullRegion:
    """The region covered by constraint points: their 2D convex hull on their best-fit plane.

    This is the crop the paper uses to show results (the convex hull of the ray intersections
    and the point constraints).

    Args:
        points: Constraint points (specular points and point constraints), shape ``(N, 3)``.
        margin: Grow the hull by this distance in world units (0 keeps exactly the hull).
        height: Also drop points farther than this from the best-fit plane (default: keep
            every distance).

    Returns:
        The region; use :meth:`HullRegion.contains` on points.

    Raises:
        InputError: If there are fewer than three points or they are collinear.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 3 or not np.all(np.isfinite(points)):
        raise InputError(
            f"region: needs at least 3 finite points to span a hull, got {len(points)}"
        )
    centre, vt = best_fit_plane(points)
    if vt is None:
        raise InputError("region: the points are collinear, they span no 2D hull")
    axes = vt[:2].copy()
    normal = np.cross(axes[0], axes[1])
    hull = _convex_hull_2d((points - centre) @ axes.T)
    return HullRegion(centre=centre, axes=axes, normal=normal, hull=hull, margin=float(margin),
                      height=None if height is None else float(height))



def crop_to_hull(mesh: trimesh.Trimesh, anchors: np.ndarray) -> trimesh.Trimesh:
    """Keep the faces whose centres fall inside the hull of ``anchors`` (the paper's figures).

    The anchors (ray intersections and point constraints) are projected onto their best-fit
    plane, and a face is kept when its centre's projection lies in their 2-D convex hull.

    Raises:
        ReconstructionError: If fewer than three anchors span a plane, or nothing is inside.
    """
    keep = hull_region(np.asarray(anchors, dtype=np.float64)).contains(mesh.triangles_center)
    if not np.any(keep):
        raise ReconstructionError("crop: no face of the mesh lies inside the constraints' hull")
    out = mesh.copy()
    out.update_faces(keep)
    out.remove_unreferenced_vertices()
    return out



HULL_ANCHORS = 4096
"""Most anchors :func:`crop_to_data_hull` builds its hulls from (an even subset beyond)."""
HULL_CHUNK = 2**22
"""Face-facet pairs tested at once by :func:`crop_to_data_hull` (32 MiB of float64)."""


def crop_to_data_hull(vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray, *,
                      margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Keep the faces whose centres lie within ``margin`` of the anchors' convex hulls.

    What an open surface's data determines: between the constraints the fit interpolates,
    beyond them it extrapolates (the back of a cylinder seen from one side, the rim of a
    patch). A centre is kept when it lies in the anchors' 3-D convex hull and in their 2-D
    hull on their best-fit plane, each grown by ``margin`` (the 3-D hull alone is a thin slab
    for flat data, whose facets reach far sideways; the 2-D one alone folds a patch that wraps
    past 180 degrees onto itself). A hull that cannot be built (too few anchors, all on a
    line or a plane) does not crop. A surface bending round an axis is better cropped by
    :func:`crop_to_unwrapped_hull`: the 3-D hull's facets cut chords under its rims.

    Returns:
        The kept vertices and faces (re-indexed).
    """
    anchors = _hull_anchors(anchors)
    faces = np.asarray(faces)
    if len(anchors) < 4 or len(faces) == 0:
        return vertices, faces
    centre = anchors.mean(axis=0)
    scale = float(np.max(np.abs(anchors - centre))) or 1.0
    a = (anchors - centre) / scale
    x = (np.asarray(vertices)[faces].mean(axis=1) - centre) / scale
    keep = np.ones(len(faces), dtype=bool)
    _, _, vt = np.linalg.svd(a, full_matrices=False)
    for points, queries in ((a, x), (a @ vt[:2].T, x @ vt[:2].T)):
        keep &= _within_hull(points, queries, margin / scale)
    return keep_faces(vertices, faces, keep)


WRAP_MIN_GAP_DEG = 30.0
"""The smallest empty arc of the anchors round the axis that :func:`crop_to_unwrapped_hull`
cuts the unwrapping at; with none as wide the anchors go all round and it does not crop."""


def crop_to_unwrapped_hull(vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray,
                           hits: np.ndarray, normals: np.ndarray, *, margin: float
                           ) -> tuple[np.ndarray, np.ndarray] | None:
    """Keep the faces of a surface bending round an axis that lie over its data, unwrapped.

    The axis is the direction the normals at the hits have least of (their smallest
    principal direction) and passes through the point nearest, in least squares, to the
    normal lines ``hits + t normals`` seen along it. Anchors and face centres are mapped to
    the surface's own coordinates round it: the arc length (the angle, cut at the middle of
    the anchors' widest empty arc, times their median distance from the axis) and the height
    along it. A face is kept when it lies within ``margin`` of the anchors' 2-D convex hull
    there. Unlike the 3-D hull, whose facets are chords cutting under a curved patch's rims
    wherever the anchors thin out, this follows the patch round; the part of the surface
    behind the data (the widest empty arc) lies outside it.

    Args:
        vertices: Mesh vertices ``(V, 3)``.
        faces: Mesh faces ``(F, 3)``.
        anchors: The constraints' positions ``(K, 3)`` (rays' hits and points).
        hits: Hits whose normals are known ``(M, 3)``.
        normals: Unit normals at ``hits`` ``(M, 3)``.
        margin: Growth of the hull in world units.

    Returns:
        The kept vertices and faces (re-indexed), or ``None`` when the normals fix no axis or
        the anchors go all round it (leave no arc of :data:`WRAP_MIN_GAP_DEG` empty).
    """
    anchors = _hull_anchors(anchors)
    hits = np.asarray(hits, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces)
    if len(anchors) < 4 or len(faces) == 0 or len(hits) < 3:
        return None
    _, _, vt = np.linalg.svd(normals, full_matrices=False)
    plane = vt[:2]
    # the axis' point: least squares over the normal lines, in the plane across the axis
    p, n = hits @ plane.T, normals @ plane.T
    length = np.linalg.norm(n, axis=1)
    ok = length > 0.5  # normals mostly across the axis
    n = n[ok] / length[ok, None]
    across = np.eye(2)[None] - n[:, :, None] * n[:, None, :]
    lhs = across.sum(axis=0)
    if ok.sum() < 2 or np.linalg.cond(lhs) > 1e6:
        return None
    centre = np.linalg.solve(lhs, np.einsum("kij,kj->i", across, p[ok]))

    def unwrap(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = x @ plane.T - centre
        return np.arctan2(d[:, 1], d[:, 0]), np.linalg.norm(d, axis=1), x @ vt[2]

    angle, radius, height = unwrap(anchors)
    order = np.sort(angle)
    gaps = np.diff(np.concatenate([order, order[:1] + 2.0 * np.pi]))
    widest = int(np.argmax(gaps))
    if np.degrees(gaps[widest]) < WRAP_MIN_GAP_DEG:
        return None
    cut = order[widest] + 0.5 * gaps[widest]
    arc = float(np.median(radius))
    if not arc > 0.0:
        return None

    def coordinates(x: np.ndarray) -> np.ndarray:
        a, _, z = unwrap(x)
        return np.stack([arc * np.mod(a - cut, 2.0 * np.pi), z], axis=1)

    scale = max(arc * 2.0 * np.pi, float(np.ptp(height))) or 1.0
    a = coordinates(anchors) / scale
    x = coordinates(np.asarray(vertices)[faces].mean(axis=1)) / scale
    return keep_faces(vertices, faces, _within_hull(a, x, margin / scale))


def _hull_anchors(anchors: np.ndarray) -> np.ndarray:
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 3)
    if len(anchors) > HULL_ANCHORS:
        # a dense cloud: its hull is as good from an even subset, and the facets stay few
        anchors = anchors[np.linspace(0, len(anchors) - 1, HULL_ANCHORS).astype(np.int64)]
    return anchors


def _within_hull(points: np.ndarray, queries: np.ndarray, margin: float) -> np.ndarray:
    """Whether each query lies within ``margin`` of the points' convex hull.

    All ``True`` when it cannot be built: too few points, or all in a lower-dimensional flat.
    """
    from scipy.spatial import ConvexHull, QhullError

    keep = np.ones(len(queries), dtype=bool)
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return keep
    d = hull.equations.shape[1] - 1
    normals, offsets = hull.equations[:, :d].T, hull.equations[:, d]
    chunk = max(1, HULL_CHUNK // len(offsets))  # bounded memory: faces x facets
    for k in range(0, len(queries), chunk):
        keep[k:k + chunk] = (queries[k:k + chunk] @ normals + offsets).max(axis=1) <= margin
    return keep


def keep_faces(vertices: np.ndarray, faces: np.ndarray, keep: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The faces ``keep`` marks, re-indexed; all of them when it marks none or all."""
    if not keep.any() or keep.all():
        return vertices, faces
    kept = faces[keep]
    used = np.unique(kept)
    index = np.full(len(vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return np.asarray(vertices)[used], index[kept]
