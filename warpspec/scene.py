"""The version-1 scene (docs/DESIGN.md section 10): loaded, validated and turned into geometry.

A :class:`Scene` holds cameras, specularities (a pixel in a camera where a highlight is seen),
point constraints, the light model and an optional domain box. Every field is validated when the
scene is built; a bad field raises :class:`~warpspec.errors.SceneError` with a one-line message
that names the field path (as in the JSON file), the value and what is expected. Input that is
legal but suspicious is reported by :meth:`Scene.check` as :class:`SceneWarning`.
"""

from __future__ import annotations

import json
import math
import os
import reprlib
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SceneError
from .geometry import (
    LIGHT_CAMERA,
    LIGHT_CODES,
    LIGHT_DIRECTIONAL,
    LIGHT_KINDS,
    LIGHT_POINT,
    best_fit_plane,
    camera_centre,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LIGHT_CAMERA",
    "LIGHT_DIRECTIONAL",
    "LIGHT_POINT",
    "Light",
    "Scene",
    "SceneWarning",
]

FORMAT_NAME = "warpspec-scene"
"""Value of the ``format`` key of a scene file."""
FORMAT_VERSION = 1
"""The scene file version this module reads and writes."""


MAX_SCENE_BYTES = 1024 * 2**20
"""Largest scene file read (1 GiB: about 15 million points in JSON)."""

# Largest condition number accepted for the left 3x3 block of a projection matrix.
_MAX_CAMERA_COND = 1e12
# A directional light closer than this to the ray direction leaves the normal undefined.
_MIN_HALF_VECTOR = 1e-9
# check() warns when the normal is more than this many degrees from the direction to the camera.
_GRAZING_DEGREES = 80.0

_TOP_KEYS = frozenset(
    {"format", "version", "cameras", "light", "specularities", "points", "domain"}
)
_CAMERA_KEYS = frozenset({"P", "light"})
_SPECULARITY_KEYS = frozenset({"camera", "pixel"})
_DOMAIN_KEYS = frozenset({"min", "max"})
_LIGHT_KEYS = {
    "directional": frozenset({"type", "direction"}),
    "point": frozenset({"type", "position"}),
    "camera": frozenset({"type"}),
}

_MISSING: Any = object()

_short = reprlib.Repr()
_short.maxlevel = 2
_short.maxlist = 4
_short.maxtuple = 4
_short.maxdict = 3
_short.maxset = 3
_short.maxstring = 40
_short.maxlong = 30
_short.maxother = 40


class SceneWarning(UserWarning):
    """Legal but suspicious scene input (a ray that misses the domain, collinear points...)."""


# --------------------------------------------------------------------------------------------
# Small validation helpers: every one raises SceneError naming the field.


def _show(value: Any) -> str:
    """Abbreviated, never-failing text of a user value for an error message."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    try:
        text = _short.repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    text = " ".join(text.split())
    return text if len(text) <= 80 else text[:77] + "..."


def _fmt(values: np.ndarray) -> str:
    """Short text of a small float vector."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in np.ravel(values)) + "]"


def _error(field: str, message: str) -> SceneError:
    return SceneError(f"{field}: {message}")


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(
        x, bool | np.bool_
    )


def _is_integer(x: Any) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool | np.bool_)


def _is_list(x: Any) -> bool:
    return isinstance(x, list | tuple | np.ndarray)


def _to_float(x: Any) -> float:
    try:
        return float(x)
    except OverflowError:  # an integer beyond the float range
        return math.inf if x > 0 else -math.inf


def _numbers(value: Any, field: str, n: int, what: str) -> np.ndarray:
    """``n`` finite numbers (a list, tuple or 1-D array) as a float64 array."""
    expected = f"expected {what}"
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf" or value.shape != (n,):
            raise _error(field, f"{expected}, got {_show(value)}")
        out = value.astype(np.float64)
    elif isinstance(value, list | tuple):
        if len(value) != n or not all(_is_number(x) for x in value):
            raise _error(field, f"{expected}, got {_show(value)}")
        out = np.array([_to_float(x) for x in value], dtype=np.float64)
    else:
        raise _error(field, f"{expected}, got {_show(value)}")
    if not np.all(np.isfinite(out)):
        raise _error(field, f"{expected}, got {_fmt(out)}")
    return out


def _matrix34(value: Any, field: str) -> np.ndarray:
    """Read a 3x4 matrix of finite numbers from nested lists or an array."""
    expected = "expected a 3x4 matrix of finite numbers"
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise _error(field, f"{expected}, got {_show(value)}")
        out = value.astype(np.float64)
    elif isinstance(value, list | tuple) and all(_is_list(row) for row in value):
        lengths = sorted({len(row) for row in value})
        if len(lengths) > 1:
            raise _error(field, f"{expected}, got rows of lengths {lengths}")
        shape = (len(value), lengths[0] if lengths else 0)
        if shape != (3, 4):
            raise _error(field, f"{expected}, got shape {shape}")
        if not all(_is_number(x) for row in value for x in row):
            raise _error(field, f"{expected}, got {_show(value)}")
        out = np.array([[_to_float(x) for x in row] for row in value], dtype=np.float64)
    else:
        raise _error(field, f"{expected}, got {_show(value)}")
    if out.shape != (3, 4):
        raise _error(field, f"{expected}, got shape {out.shape}")
    bad = np.argwhere(~np.isfinite(out))
    if len(bad):
        i, j = (int(k) for k in bad[0])
        raise _error(field, f"{expected}, got {out[i, j]} at row {i}, column {j}")
    return out


def _float_array(
    value: Any, field: str, tail: tuple[int, ...], what: str, row: Callable[[int], str]
) -> np.ndarray:
    """Copy to a float64 array of shape ``(n, *tail)`` with finite entries (``None``: empty)."""
    if value is None:
        return np.zeros((0, *tail))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = np.array(value)
    except Exception:
        raise _error(field, f"expected {what}, got {_show(value)}") from None
    if arr.size == 0:
        return np.zeros((0, *tail))
    if arr.dtype.kind not in "iuf":
        raise _error(field, f"expected {what}, got {_show(value)}")
    arr = arr.astype(np.float64)
    if arr.shape[1:] != tail or arr.ndim != len(tail) + 1:
        raise _error(field, f"expected {what}, got shape {arr.shape}")
    bad = ~np.isfinite(arr.reshape(len(arr), -1)).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise _error(row(i), f"expected finite numbers, got {_fmt(arr[i])}")
    return arr


def _points_fast(rows: Sequence[Any]) -> np.ndarray | None:
    """Rows of exactly 3 finite JSON numbers as an ``(n, 3)`` array in one pass, else ``None``.

    A million points take a fraction of a second here, against ten seconds row by row; any
    other input (a bool, a string, a ragged row) returns ``None`` for the row-by-row check.
    """
    if not all(type(r) is list and len(r) == 3 for r in rows):
        return None
    if not all(type(x) is float or type(x) is int for r in rows for x in r):
        return None
    try:
        arr = np.array(rows, dtype=np.float64)
    except (OverflowError, ValueError):
        return None
    return arr if np.isfinite(arr).all() else None


def _camera_indices(value: Any, num_cameras: int) -> np.ndarray:
    """Validate the integer camera indices of the specularities (``None``: empty)."""
    if value is None:
        return np.zeros(0, dtype=np.int64)
    if isinstance(value, np.ndarray):
        if value.size == 0:
            return np.zeros(0, dtype=np.int64)
        if value.ndim != 1 or value.dtype.kind not in "iu":
            raise _error(
                "specularities",
                f"expected a 1-D array of integer camera indices, got {_show(value)}",
            )
        items: Sequence[Any] = value.tolist()
    elif isinstance(value, list | tuple):
        items = value
    else:
        raise _error("specularities", f"expected a list of camera indices, got {_show(value)}")
    for i, x in enumerate(items):
        field = f"specularities[{i}].camera"
        if not _is_integer(x):
            raise _error(field, f"expected an integer camera index, got {_show(x)}")
        if not 0 <= x < num_cameras:
            raise _error(
                field, f"index {_show(x)} out of range, the scene has {num_cameras} cameras"
            )
    return np.array([int(x) for x in items], dtype=np.int64)


def _box(value: Any, field: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate a ``(min, max)`` box (or ``{"min", "max"}``) with ``max > min`` on every axis."""
    if isinstance(value, Mapping):
        if "min" not in value or "max" not in value:
            raise _error(
                field, f'expected {{"min": [x, y, z], "max": [x, y, z]}}, got {_show(value)}'
            )
        value = (value["min"], value["max"])
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise _error(field, f"expected a pair (min, max) of 3-vectors, got {_show(value)}")
    lo = _numbers(value[0], f"{field}.min", 3, "3 finite numbers [x, y, z]")
    hi = _numbers(value[1], f"{field}.max", 3, "3 finite numbers [x, y, z]")
    with np.errstate(over="ignore", invalid="ignore"):
        extent = hi - lo
    if not np.all(np.isfinite(extent)) or np.any(extent <= 0):
        raise _error(field, f"max must exceed min on every axis, got min={_fmt(lo)} max={_fmt(hi)}")
    return lo, hi


def _pixel_directions(cameras: np.ndarray, camera: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Unit directions ``normalize(sign(det M) M^-1 (u, v, 1))`` of ``pixels`` in ``camera``.

    Zero rows where a direction is not finite (the caller says which).
    """
    q = np.concatenate([pixels, np.ones((len(pixels), 1))], axis=1)
    q /= np.max(np.abs(q), axis=1, keepdims=True) if len(q) else 1.0
    M = cameras[:, :, :3]
    with np.errstate(all="ignore"):
        sign = np.linalg.slogdet(M)[0]  # robust to under/overflow of det
        d = np.linalg.solve(M[camera], q[:, :, None])[:, :, 0] * sign[camera, None]
    return _unit_rows(d)


def _unit_rows(a: np.ndarray) -> np.ndarray:
    """Rows of ``a`` scaled to unit length without overflow; zero or non-finite rows become 0."""
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(all="ignore"):
        scale = np.max(np.abs(a), axis=-1, keepdims=True)
        ok = np.isfinite(scale) & (scale > 0)
        b = np.where(ok, a / np.where(ok, scale, 1.0), 0.0)
        norm = np.linalg.norm(b, axis=-1, keepdims=True)
        return np.where(ok, b / np.where(ok, norm, 1.0), 0.0)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def _note_unknown(data: Mapping, known: frozenset, field: str, sink: list[str]) -> None:
    """Record keys of ``data`` that the format does not define (``_``-prefixed keys are free)."""
    for key in data:
        if key not in known and not (isinstance(key, str) and key.startswith("_")):
            sink.append(f"{field}.{key}" if isinstance(key, str) else f"{field}[{_show(key)}]")


def _warn_unknown(sink: list[str]) -> None:
    if sink:
        shown = ", ".join(sink[:8]) + (f" and {len(sink) - 8} more" if len(sink) > 8 else "")
        warnings.warn(f"unknown scene keys ignored: {shown}", SceneWarning, stacklevel=3)


# --------------------------------------------------------------------------------------------
# Light


def _light_vector(kind: str, vector: Any, field: str) -> np.ndarray | None:
    """Validate the vector of a light of a known kind; directions come back normalised."""
    if kind == "camera":
        if vector is not None:
            raise _error(field, f"a camera light takes no vector, got {_show(vector)}")
        return None
    key = "direction" if kind == "directional" else "position"
    if vector is None:
        raise _error(f"{field}.{key}", "missing, expected 3 finite numbers [x, y, z]")
    v = _numbers(vector, f"{field}.{key}", 3, "3 finite numbers [x, y, z]")
    if kind == "directional":
        if not np.any(v != 0):
            raise _error(f"{field}.direction", "expected a non-zero vector, got [0, 0, 0]")
        with np.errstate(all="ignore"):
            unit = abs(float(np.dot(v, v)) - 1.0) <= 1e-15
        if not unit:  # a unit vector stays as it is, so a saved scene loads back identical
            v = _unit_rows(v)
    return _readonly(v)


@dataclass(frozen=True, eq=False)
class Light:
    """The light that makes the highlights.

    Attributes:
        kind: ``"directional"``, ``"point"`` or ``"camera"`` (a flash at each camera centre).
        vector: For a directional light the unit vector from the surface toward the light
            (normalised on construction); for a point light its position; ``None`` for a camera
            light. Stored as a read-only copy.

    """

    kind: str
    vector: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in LIGHT_CODES:
            raise _error(
                "light.type", f"unknown light type {_show(self.kind)}, expected {LIGHT_KINDS}"
            )
        object.__setattr__(self, "vector", _light_vector(self.kind, self.vector, "light"))

    @property
    def code(self) -> int:
        """The ``LIGHT_*`` code of this kind, as used by the Warp kernels."""
        return LIGHT_CODES[self.kind]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Light):
            return NotImplemented
        if self.kind != other.kind:
            return False
        if self.vector is None or other.vector is None:
            return self.vector is None and other.vector is None
        return bool(np.array_equal(self.vector, other.vector))

    def __hash__(self) -> int:
        vec = None if self.vector is None else tuple(self.vector.tolist())
        return hash((self.kind, vec))

    def __repr__(self) -> str:
        vec = "" if self.vector is None else f", vector={_fmt(self.vector)}"
        return f"Light({self.kind!r}{vec})"

    @classmethod
    def from_dict(cls, data: Mapping, *, field: str = "light") -> Light:
        """Build a light from its JSON object, e.g. ``{"type": "point", "position": [x, y, z]}``.

        Args:
            data: The JSON object.
            field: Field path used in error messages (``"cameras[2].light"``).

        Raises:
            SceneError: If the object is not a valid light; the message names ``field``.

        """
        unknown: list[str] = []
        light = _light_from_dict(data, field, unknown)
        _warn_unknown(unknown)
        return light

    def to_dict(self) -> dict:
        """Return the JSON object of this light."""
        if self.kind == "directional":
            return {"type": "directional", "direction": self.vector.tolist()}
        if self.kind == "point":
            return {"type": "point", "position": self.vector.tolist()}
        return {"type": "camera"}


def _light_from_dict(data: Any, field: str, unknown: list[str]) -> Light:
    if not isinstance(data, Mapping):
        raise _error(
            field,
            'expected an object like {"type": "directional", "direction": [x, y, z]}, '
            f"got {_show(data)}",
        )
    kind = data.get("type", _MISSING)
    if kind is _MISSING:
        raise _error(f"{field}.type", f"missing, expected {LIGHT_KINDS}")
    if not isinstance(kind, str) or kind not in LIGHT_CODES:
        raise _error(f"{field}.type", f"unknown light type {_show(kind)}, expected {LIGHT_KINDS}")
    _note_unknown(data, _LIGHT_KEYS[kind], field, unknown)
    if kind == "camera":
        return Light("camera")
    key = "direction" if kind == "directional" else "position"
    vector = data.get(key, _MISSING)
    if vector is _MISSING or vector is None:
        raise _error(f"{field}.{key}", "missing, expected 3 finite numbers [x, y, z]")
    return Light(kind, _light_vector(kind, vector, field))


def _as_light(value: Any, field: str) -> Light | None:
    if value is None or isinstance(value, Light):
        return value
    if isinstance(value, Mapping):
        return Light.from_dict(value, field=field)
    raise _error(field, f"expected a Light or None, got {_show(value)}")


# --------------------------------------------------------------------------------------------
# Scene


class Scene:
    """A validated version-1 scene and the geometry derived from it.

    The arrays are read-only copies of the input, so a scene never changes after validation.

    Attributes:
        cameras: Projection matrices ``P``, shape ``(C, 3, 4)``, float64.
        spec_camera: Camera index of each specularity, shape ``(M,)``, int64.
        spec_pixel: Pixel ``(u, v)`` of each specularity, shape ``(M, 2)``, float64.
        points: Point constraints, shape ``(K, 3)``, float64.
        light: The scene's light, or ``None``.
        camera_lights: Per camera, its own light (which overrides the scene's) or ``None``.
        domain: The domain box ``(min, max)``, or ``None`` to derive it from the points.

    """

    def __init__(
        self,
        cameras: Any,
        specularities_camera: Any,
        specularities_pixel: Any,
        points: Any,
        *,
        light: Light | None = None,
        camera_lights: Sequence[Light | None] | None = None,
        domain: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Validate and copy the scene's data.

        Args:
            cameras: Projection matrices, shape ``(C, 3, 4)``; at least one.
            specularities_camera: Camera index of each specularity, shape ``(M,)``, integers.
            specularities_pixel: Pixel ``(u, v)`` of each specularity, shape ``(M, 2)``.
            points: Point constraints, shape ``(K, 3)``; ``None`` or empty for none.
            light: The scene's light (a :class:`Light` or its JSON object).
            camera_lights: Per camera a light that overrides ``light``, or ``None``.
            domain: The box ``(min, max)`` to reconstruct in; ``None`` derives it.

        Raises:
            SceneError: If any input is invalid; the message names the field as in the JSON
                file (``cameras[3].P``, ``specularities[5].camera``...).

        """
        cams = _float_array(
            cameras,
            "cameras",
            (3, 4),
            "a list of 3x4 matrices of finite numbers",
            lambda i: f"cameras[{i}].P",
        )
        if len(cams) == 0:
            raise _error("cameras", "the scene has no cameras, expected at least one")
        centres = np.empty((len(cams), 3))
        for i, P in enumerate(cams):
            centres[i] = _camera_centre(P, f"cameras[{i}].P")
        num_cameras = len(cams)

        scene_light = _as_light(light, "light")
        if camera_lights is None:
            cam_lights: tuple[Light | None, ...] = (None,) * num_cameras
        else:
            if not isinstance(camera_lights, Sequence) or isinstance(camera_lights, str | bytes):
                raise _error(
                    "camera_lights",
                    f"expected one light or None per camera, got {_show(camera_lights)}",
                )
            if len(camera_lights) != num_cameras:
                raise _error(
                    "camera_lights",
                    f"expected {num_cameras} entries (one per camera), got {len(camera_lights)}",
                )
            cam_lights = tuple(
                _as_light(x, f"cameras[{i}].light") for i, x in enumerate(camera_lights)
            )

        spec_camera = _camera_indices(specularities_camera, num_cameras)
        spec_pixel = _float_array(
            specularities_pixel,
            "specularities",
            (2,),
            "an array of pixels of shape (M, 2)",
            lambda i: f"specularities[{i}].pixel",
        )
        if len(spec_camera) != len(spec_pixel):
            raise _error(
                "specularities",
                f"{len(spec_camera)} camera indices but {len(spec_pixel)} pixels, expected as many",
            )
        pts = _float_array(
            points, "points", (3,), "a list of [x, y, z] points", lambda i: f"points[{i}]"
        )
        box = None if domain is None else _box(domain, "domain")
        if len(spec_camera) == 0 and len(pts) == 0:
            raise _error("scene", "no constraints: give at least one specularity or one point")
        for i, c in enumerate(spec_camera.tolist()):
            if cam_lights[c] is None and scene_light is None:
                raise _error(
                    "light",
                    f"missing: specularities[{i}] is seen in camera {c}, which needs a scene "
                    f'"light" or cameras[{c}].light',
                )

        directions = _pixel_directions(cams, spec_camera, spec_pixel)
        for i in np.flatnonzero(~np.any(directions != 0, axis=1)):
            raise _error(
                f"specularities[{i}].pixel",
                f"the ray of {_fmt(spec_pixel[i])} in camera {spec_camera[i]} is not finite",
            )

        self.cameras = _readonly(cams)
        self.spec_camera = _readonly(spec_camera)
        self.spec_pixel = _readonly(spec_pixel)
        self.points = _readonly(pts)
        self.light = scene_light
        self.camera_lights = cam_lights
        self.domain = None if box is None else (_readonly(box[0]), _readonly(box[1]))
        self._centres = _readonly(centres)
        self._directions = _readonly(directions)

        codes, vectors = self.ray_lights()
        for i in np.flatnonzero(codes == LIGHT_DIRECTIONAL):
            if np.linalg.norm(vectors[i] - directions[i]) < _MIN_HALF_VECTOR:
                raise _error(
                    f"specularities[{i}]",
                    "the light direction equals the ray direction (the light is straight "
                    "behind the surface), so no normal satisfies the reflection law",
                )

    # ---------------------------------------------------------------------------- file format

    @classmethod
    def from_dict(cls, data: Mapping) -> Scene:
        """Build a scene from its JSON object (docs/DESIGN.md section 10).

        Unknown keys are ignored with a :class:`SceneWarning`, except those starting with ``_``.

        Args:
            data: The parsed JSON object.

        Raises:
            SceneError: If any field is missing or invalid; the message names it.

        """
        if not isinstance(data, Mapping):
            raise _error("scene", f"expected a JSON object at the top level, got {_show(data)}")
        unknown: list[str] = []
        _note_unknown(data, _TOP_KEYS, "scene", unknown)
        unknown = [k.removeprefix("scene.") for k in unknown]

        fmt = data.get("format", _MISSING)
        if fmt is _MISSING:
            raise _error("format", f'missing, expected "{FORMAT_NAME}"')
        if not isinstance(fmt, str) or fmt != FORMAT_NAME:
            raise _error("format", f'expected "{FORMAT_NAME}", got {_show(fmt)}')
        version = data.get("version", _MISSING)
        if version is _MISSING:
            raise _error("version", f"missing, expected {FORMAT_VERSION}")
        if not _is_integer(version) or version != FORMAT_VERSION:
            raise _error(
                "version", f"unsupported version {_show(version)}, expected {FORMAT_VERSION}"
            )

        cameras_data = data.get("cameras", _MISSING)
        if cameras_data is _MISSING or cameras_data is None:
            raise _error("cameras", 'missing, expected a list of cameras {"P": 3x4 matrix}')
        if not isinstance(cameras_data, list | tuple):
            raise _error("cameras", f"expected a list of cameras, got {_show(cameras_data)}")
        if len(cameras_data) == 0:
            raise _error("cameras", "the scene has no cameras, expected at least one")
        matrices = []
        camera_lights: list[Light | None] = []
        for i, cam in enumerate(cameras_data):
            field = f"cameras[{i}]"
            if not isinstance(cam, Mapping):
                raise _error(field, f'expected an object {{"P": 3x4 matrix}}, got {_show(cam)}')
            _note_unknown(cam, _CAMERA_KEYS, field, unknown)
            P = cam.get("P", _MISSING)
            if P is _MISSING:
                raise _error(f"{field}.P", "missing, expected a 3x4 matrix of finite numbers")
            matrices.append(_matrix34(P, f"{field}.P"))
            cam_light = cam.get("light")
            camera_lights.append(
                None
                if cam_light is None
                else _light_from_dict(cam_light, f"{field}.light", unknown)
            )

        light_data = data.get("light")
        light = None if light_data is None else _light_from_dict(light_data, "light", unknown)

        specs = data.get("specularities")
        specs = [] if specs is None else specs
        if not isinstance(specs, list | tuple):
            raise _error(
                "specularities",
                f'expected a list of {{"camera": index, "pixel": [u, v]}}, got {_show(specs)}',
            )
        spec_camera: list[int] = []
        spec_pixel: list[np.ndarray] = []
        for i, spec in enumerate(specs):
            field = f"specularities[{i}]"
            if not isinstance(spec, Mapping):
                raise _error(
                    field,
                    f'expected an object {{"camera": index, "pixel": [u, v]}}, got {_show(spec)}',
                )
            _note_unknown(spec, _SPECULARITY_KEYS, field, unknown)
            cam = spec.get("camera", _MISSING)
            if cam is _MISSING:
                raise _error(f"{field}.camera", "missing, expected an integer camera index")
            if not _is_integer(cam):
                raise _error(
                    f"{field}.camera", f"expected an integer camera index, got {_show(cam)}"
                )
            if not 0 <= cam < len(matrices):
                raise _error(
                    f"{field}.camera",
                    f"index {_show(cam)} out of range, the scene has {len(matrices)} cameras",
                )
            pixel = spec.get("pixel", _MISSING)
            if pixel is _MISSING:
                raise _error(f"{field}.pixel", "missing, expected two finite numbers [u, v]")
            spec_camera.append(int(cam))
            spec_pixel.append(_numbers(pixel, f"{field}.pixel", 2, "two finite numbers [u, v]"))

        points_data = data.get("points")
        points_data = [] if points_data is None else points_data
        if isinstance(points_data, np.ndarray) and points_data.ndim == 2:
            points_data = list(points_data)
        if not isinstance(points_data, list | tuple):
            raise _error("points", f"expected a list of [x, y, z] points, got {_show(points_data)}")
        points = _points_fast(points_data)
        if points is None:  # not plain rows of 3 finite numbers: find the bad one and name it
            points = [
                _numbers(p, f"points[{i}]", 3, "3 finite numbers [x, y, z]")
                for i, p in enumerate(points_data)
            ]

        domain_data = data.get("domain")
        domain = None
        if domain_data is not None:
            if not isinstance(domain_data, Mapping):
                raise _error(
                    "domain",
                    'expected an object {"min": [x, y, z], "max": [x, y, z]}, '
                    f"got {_show(domain_data)}",
                )
            _note_unknown(domain_data, _DOMAIN_KEYS, "domain", unknown)
            for key in ("min", "max"):
                if key not in domain_data:
                    raise _error(f"domain.{key}", "missing, expected 3 finite numbers [x, y, z]")
            domain = _box((domain_data["min"], domain_data["max"]), "domain")

        scene = cls(
            np.array(matrices),
            np.array(spec_camera, dtype=np.int64),
            np.array(spec_pixel).reshape(-1, 2),
            np.array(points).reshape(-1, 3),
            light=light,
            camera_lights=camera_lights,
            domain=domain,
        )
        _warn_unknown(unknown)
        return scene

    def to_dict(self) -> dict:
        """Return the JSON object of this scene; :meth:`from_dict` of it gives equal arrays."""
        cameras = []
        for P, cam_light in zip(self.cameras, self.camera_lights, strict=True):
            cam: dict[str, Any] = {"P": P.tolist()}
            if cam_light is not None:
                cam["light"] = cam_light.to_dict()
            cameras.append(cam)
        out: dict[str, Any] = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "cameras": cameras}
        if self.light is not None:
            out["light"] = self.light.to_dict()
        out["specularities"] = [
            {"camera": int(c), "pixel": p.tolist()}
            for c, p in zip(self.spec_camera, self.spec_pixel, strict=True)
        ]
        out["points"] = self.points.tolist()
        if self.domain is not None:
            out["domain"] = {"min": self.domain[0].tolist(), "max": self.domain[1].tolist()}
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> Scene:
        """Read a scene from a JSON file.

        Args:
            path: The file.

        Raises:
            SceneError: If the file is missing or unreadable, is not JSON, or any field is
                invalid.

        """
        where = _path_text(path)
        from ._atomic import check_size

        check_size(path, MAX_SCENE_BYTES, where)
        try:
            raw = Path(path).read_bytes()
        except FileNotFoundError:
            raise _error(where, "no such scene file") from None
        except IsADirectoryError:
            raise _error(where, "is a directory, expected a scene JSON file") from None
        except (OSError, ValueError, TypeError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise _error(where, f"cannot read the scene file ({reason})") from None
        try:
            data = json.loads(raw, object_pairs_hook=_no_duplicate_keys)
        except json.JSONDecodeError as exc:
            raise _error(
                where, f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
            ) from None
        except UnicodeDecodeError:
            raise _error(where, "not valid JSON: the file is not UTF-8 text") from None
        except RecursionError:
            raise _error(where, "not a scene: the JSON is nested too deeply") from None
        except _DuplicateKey as exc:
            raise _error(
                where, f"not a valid scene: duplicate key {exc.args[0]!r} in an object"
            ) from None
        except ValueError as exc:  # e.g. an integer literal with too many digits
            raise _error(where, f"not valid JSON: {' '.join(str(exc).split())[:120]}") from None
        return cls.from_dict(data)

    def save(self, path: str | os.PathLike) -> None:
        """Write the scene as a JSON file.

        The file is written to a unique temporary file beside it and renamed: a failure (a
        full disk) leaves a file already at ``path`` as it was.

        Args:
            path: The file; it is replaced.

        Raises:
            SceneError: If the file cannot be written.

        """
        from ._atomic import atomic_write

        where = _path_text(path)
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False)
        try:
            atomic_write(path, lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))
        except (OSError, ValueError, TypeError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise _error(where, f"cannot write the scene file ({reason})") from None

    # ---------------------------------------------------------------------------- geometry

    def __repr__(self) -> str:
        light = "None" if self.light is None else self.light.kind
        return (
            f"Scene({self.num_cameras} cameras, {self.num_specularities} specularities, "
            f"{self.num_points} points, light={light})"
        )

    @property
    def num_cameras(self) -> int:
        """Number of cameras ``C``."""
        return len(self.cameras)

    @property
    def num_specularities(self) -> int:
        """Number of specularities ``M`` (specular rays)."""
        return len(self.spec_camera)

    @property
    def num_points(self) -> int:
        """Number of point constraints ``K``."""
        return len(self.points)

    def camera_centres(self) -> np.ndarray:
        """Return the camera centres ``c = -M^-1 p4``, shape ``(C, 3)``."""
        return self._centres.copy()

    def rays(self, *, shift: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """Return the specular rays.

        Args:
            shift: Pixels added to every specularity's ``(u, v)`` first: the rays of
                highlights moved so (how far a highlight must move to meet a shape,
                docs/DESIGN.md section 7).

        Returns:
            Origins, shape ``(M, 3)``: the centre of each specularity's camera; and unit
            directions, shape ``(M, 3)``: ``normalize(sign(det M) M^-1 (u, v, 1))``, pointing
            from the camera into the scene.

        """
        return self._centres[self.spec_camera], self._shifted_directions(shift)

    def pixel_angles(self) -> np.ndarray:
        """Return each ray's pixel as an angle.

        How far its direction turns as its highlight moves one pixel, the mean over ``u`` and
        ``v`` (radians, the chord of the turn).

        Returns:
            Angles, shape ``(M,)``: about ``1 / focal`` near the principal point.

        """
        return 0.5 * sum(np.linalg.norm(self._shifted_directions(shift) - self._directions,
                                        axis=1) for shift in ((1.0, 0.0), (0.0, 1.0)))

    def _shifted_directions(self, shift: tuple[float, float]) -> np.ndarray:
        """The rays' unit directions with ``shift`` added to every pixel (a copy).

        Raises:
            SceneError: If ``shift`` is not two finite numbers.
        """
        try:
            du, dv = (float(x) for x in shift)
        except (TypeError, ValueError):
            du = dv = math.nan
        if not (math.isfinite(du) and math.isfinite(dv)):
            raise _error("shift", f"expected two finite pixel offsets (du, dv), got {shift!r}")
        if du == 0.0 and dv == 0.0:
            return self._directions.copy()
        directions = _pixel_directions(self.cameras, self.spec_camera,
                                       self.spec_pixel + np.array([du, dv]))
        if not np.all(np.any(directions != 0, axis=1)):
            raise _error("shift", f"{shift!r} moves a highlight to a pixel with no finite ray")
        return directions

    def ray_lights(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the light of each specularity; a camera's own light overrides the scene's.

        Returns:
            Light codes ``LIGHT_*``, shape ``(M,)``, int32; and light vectors, shape ``(M, 3)``,
            float64: the unit direction toward a directional light, the position of a point
            light, zeros for a camera light.

        """
        m = self.num_specularities
        codes = np.empty(m, dtype=np.int32)
        vectors = np.zeros((m, 3))
        for i, c in enumerate(self.spec_camera.tolist()):
            light = self.camera_lights[c] or self.light
            codes[i] = light.code
            if light.vector is not None:
                vectors[i] = light.vector
        return codes, vectors

    def normals(self, points: np.ndarray | None = None, *,
                shift: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """Surface normals demanded by the reflection law, ``N = normalize(L - r)``.

        ``L`` is the unit vector toward the light: constant for a directional light,
        ``normalize(p - x)`` for a point light at ``p``, ``-r`` for a camera flash (so
        ``N = -r``). Where ``L - r`` vanishes (a point light straight behind ``x``) ``N = -r``.

        Args:
            points: Where each ray meets the surface, shape ``(M, 3)``; needed only when a
                point light is in use.
            shift: Pixels added to every specularity first, as in :meth:`rays`.

        Returns:
            Unit normals, shape ``(M, 3)``.

        Raises:
            SceneError: If a point light is in use and ``points`` is missing or invalid.

        """
        m = self.num_specularities
        codes, vectors = self.ray_lights()
        r = self._shifted_directions(shift)
        L = np.zeros((m, 3))
        directional = codes == LIGHT_DIRECTIONAL
        L[directional] = vectors[directional]
        camera = codes == LIGHT_CAMERA
        L[camera] = -r[camera]
        point = codes == LIGHT_POINT
        x = None
        if points is not None:
            x = _float_array(
                points, "points", (3,), f"an array of shape ({m}, 3)", lambda i: f"points[{i}]"
            )
            if len(x) != m:
                raise _error("points", f"expected {m} surface points (one per ray), got {len(x)}")
        if point.any():
            if x is None:
                raise _error(
                    "points",
                    "a point light is in use: pass the surface points x (M, 3) where the rays "
                    "meet the surface",
                )
            with np.errstate(all="ignore"):
                L[point] = _unit_rows(vectors[point] - x[point])
        n = _unit_rows(L - r)
        degenerate = ~np.any(n != 0, axis=1)
        n[degenerate] = -r[degenerate]
        return n

    def translated(self, origin: Any) -> Scene:
        """The same scene measured from ``origin``: a world point ``x`` is ``x - origin`` in it.

        Cameras, points, point lights and the domain move; directions, pixels and rays'
        angles do not. The solver works about its grid's centre (docs/DESIGN.md section 3):
        a fit of normal lines or a quadric to coordinates far from the origin loses the
        digits that tell the shape.

        Raises:
            SceneError: If ``origin`` is not three finite numbers.
        """
        o = _numbers(origin, "origin", 3, "a point [x, y, z]")
        shift = np.eye(4)
        shift[:3, 3] = o  # world = local + origin

        def move(light: Light | None) -> Light | None:
            point = light is not None and light.kind == "point"
            return Light("point", light.vector - o) if point else light

        domain = None if self.domain is None else (self.domain[0] - o, self.domain[1] - o)
        return Scene(self.cameras @ shift, self.spec_camera, self.spec_pixel,
                     self.points - o if len(self.points) else None, light=move(self.light),
                     camera_lights=[move(li) for li in self.camera_lights], domain=domain)

    def bounds(self, *, margin: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
        """Return the box to reconstruct in.

        Args:
            margin: Without a domain, the bounding box of the points grows by
                ``margin * (longest side)`` on every side.

        Returns:
            ``(min, max)``: the domain if the scene has one, else the grown bounding box.

        Raises:
            SceneError: If there is no domain and fewer than 2 distinct points, or the grown box
                is flat on some axis, or ``margin`` is not a finite number ``>= 0``.

        """
        if not _is_number(margin) or not math.isfinite(margin) or margin < 0:
            raise _error("margin", f"expected a finite number >= 0, got {_show(margin)}")
        if self.domain is not None:
            return self.domain[0].copy(), self.domain[1].copy()
        distinct = len(np.unique(self.points, axis=0)) if len(self.points) else 0
        if distinct < 2:
            raise _error(
                "domain",
                f"cannot be derived from {distinct} distinct point(s); give "
                '"domain": {"min": [x, y, z], "max": [x, y, z]}',
            )
        with np.errstate(all="ignore"):
            lo, hi = self.points.min(axis=0), self.points.max(axis=0)
            grow = float(margin) * float(np.max(hi - lo))
            lo, hi = lo - grow, hi + grow
            extent = hi - lo
        if not np.all(np.isfinite(extent)):
            raise _error(
                "domain",
                f"the box derived from the points overflows, min={_fmt(lo)} max={_fmt(hi)}; "
                'give "domain"',
            )
        if np.any(extent <= 0):
            raise _error(
                "domain",
                f"the box derived from the points is flat, min={_fmt(lo)} max={_fmt(hi)}; "
                'use a positive margin or give "domain"',
            )
        return lo, hi

    def check(self, *, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> list[str]:
        """Look for legal but suspicious input; each finding is also warned as SceneWarning.

        Reports specular rays that never enter the box or point away from it, points outside
        the box, normals almost perpendicular to the direction back to the camera (a
        directional light given with the wrong sign, say; directional and camera lights only),
        and point constraints that are all collinear.

        Args:
            bounds: The box ``(min, max)``; default :meth:`bounds`.

        Returns:
            The warning messages, one line each.

        Raises:
            SceneError: If ``bounds`` is given and is not a valid box.

        """
        messages: list[str] = []
        box = None
        if bounds is not None:
            box = _box(bounds, "bounds")
        else:
            try:
                box = self.bounds()
            except SceneError as exc:
                messages.append(str(exc))

        origins, dirs = self.rays()
        if box is not None:
            lo, hi = box
            hits, ahead = _ray_box(origins, dirs, lo, hi)
            where = f"the domain box min={_fmt(lo)} max={_fmt(hi)}"
            for i in range(self.num_specularities):
                ray = f"the ray of pixel {_fmt(self.spec_pixel[i])} in camera {self.spec_camera[i]}"
                if not hits[i]:
                    messages.append(f"specularities[{i}]: {ray} never enters {where}")
                elif not ahead[i]:
                    messages.append(
                        f"specularities[{i}]: {ray} points away from {where} (behind the camera)"
                    )
            outside = np.any((self.points < lo) | (self.points > hi), axis=1)
            for i in np.flatnonzero(outside):
                messages.append(f"points[{i}]: {_fmt(self.points[i])} lies outside {where}")

        codes, vectors = self.ray_lights()
        directional = codes == LIGHT_DIRECTIONAL
        if directional.any():
            # N = normalize(L - r); a camera light gives N = -r, which always faces the camera.
            n = _unit_rows(vectors[directional] - dirs[directional])
            cosine = np.einsum("ij,ij->i", n, -dirs[directional])
            limit = math.cos(math.radians(_GRAZING_DEGREES))
            for j in np.flatnonzero(cosine <= limit):
                i = int(np.flatnonzero(directional)[j])
                angle = math.degrees(math.acos(float(np.clip(cosine[j], -1.0, 1.0))))
                messages.append(
                    f"specularities[{i}]: the normal makes {angle:.1f} degrees with the direction "
                    f"back to camera {self.spec_camera[i]} (the light is nearly behind the "
                    "surface); check that the light direction points from the surface toward "
                    "the light"
                )

        if self.num_points >= 3 and best_fit_plane(self.points)[1] is None:
            messages.append(
                f"points: all {self.num_points} points are collinear, so they do not "
                "determine the initial plane"
            )

        for message in messages:
            warnings.warn(message, SceneWarning, stacklevel=2)
        return messages


# --------------------------------------------------------------------------------------------
# Geometry helpers


def _camera_centre(P: np.ndarray, field: str) -> np.ndarray:
    """Centre ``-M^-1 p4`` of a finite camera; SceneError if ``M`` is (nearly) singular."""
    M = P[:, :3]
    with np.errstate(all="ignore"):
        try:
            cond = float(np.linalg.cond(M))
        except np.linalg.LinAlgError:
            cond = math.inf
        if not math.isfinite(cond) or cond > _MAX_CAMERA_COND:
            raise _error(
                field,
                "expected a finite camera, got a singular left 3x3 block "
                f"(condition number {cond:.3g}, at most {_MAX_CAMERA_COND:.0e} accepted)",
            )
        centre = camera_centre(P)
    if not np.all(np.isfinite(centre)):
        raise _error(field, "the camera centre -M^-1 p4 is not finite (badly scaled matrix)")
    return centre


def ray_box_span(
    origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slab test: where each ray's line ``o + t d`` enters and leaves the box ``[lo, hi]``.

    Returns:
        ``(near, far)``, the parameters ``t`` of the entry and the exit ``(M,)`` (``near >
        far``: the line misses the box; a direction component of 0 inside its slab, faces
        included, bounds nothing).
    """
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = 1.0 / dirs
        t1 = (lo - origins) * inv
        t2 = (hi - origins) * inv
    parallel = dirs == 0
    inside = (origins >= lo) & (origins <= hi)
    tmin = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    tmax = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    near = tmin.max(axis=1) if len(tmin) else np.zeros(0)
    far = tmax.min(axis=1) if len(tmax) else np.zeros(0)
    return near, far


def _ray_box(
    origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slab test: whether each ray's line meets the box, and whether it does so ahead (t >= 0)."""
    near, far = ray_box_span(origins, dirs, lo, hi)
    hits = near <= far
    return hits, hits & (far >= 0)


def rays_meet_box(
    origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """Whether each ray (not its backward half) enters the box ``[lo, hi]``."""
    return _ray_box(origins, dirs, lo, hi)[1]


class _DuplicateKey(Exception):
    pass


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _path_text(path: Any) -> str:
    if not isinstance(path, str | os.PathLike):
        raise _error("path", f"expected a file path, got {_show(path)}")
    try:
        return f"scene file {os.fspath(path)!r}"
    except TypeError:
        raise _error("path", f"expected a file path, got {_show(path)}") from None
