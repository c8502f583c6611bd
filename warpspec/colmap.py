"""Import a COLMAP text model and a CSV of highlights as a warpspec :class:`~warpspec.Scene`.

COLMAP (https://colmap.github.io) is the structure-from-motion tool most people use to get
cameras and sparse 3D points from photographs. Its text model is three files in one folder
(``colmap model_converter --output_type TXT`` writes them from a binary model):

- ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``, one camera (intrinsics) a line;
- ``images.txt``: two lines per registered image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID
  NAME`` and then its ``POINTS2D[]`` as ``(X, Y, POINT3D_ID)`` triples (the line may be empty);
  the quaternion and translation map world to camera coordinates, ``x_cam = R x_world + t``;
- ``points3D.txt``: ``POINT3D_ID X Y Z R G B ERROR TRACK[]`` with the track as
  ``(IMAGE_ID, POINT2D_IDX)`` pairs.

Lines starting with ``#`` are comments. Every registered image becomes a warpspec camera
``P = K [R | t]``, in increasing ``IMAGE_ID`` order (``ColmapImport.image_names`` gives each
camera's image); the model's 3D points become point constraints.

Camera models: ``SIMPLE_PINHOLE`` (f, cx, cy), ``PINHOLE`` (fx, fy, cx, cy), and
``SIMPLE_RADIAL`` (f, cx, cy, k), ``RADIAL`` (f, cx, cy, k1, k2), ``OPENCV`` (fx, fy, cx, cy,
k1, k2, p1, p2), whose lens distortion is ignored with a :class:`~warpspec.SceneWarning` that
says how far it would move the highlights (undistort the images with ``colmap
image_undistorter`` to get a ``PINHOLE`` model and no error). Other models are refused.

Highlights come as a CSV file of ``image,u,v`` rows: the image's ``NAME`` as in
``images.txt`` (or its base name when that is unique) and the pixel of the highlight's centre.
A header row (``image,u,v``; also ``name``/``x``/``y``) is optional, as are blank lines and
``#`` comments.

Pixel convention: by default (``pixel_convention="colmap"``) ``u, v`` are in COLMAP's own
convention, the one its intrinsics and keypoints use: ``u`` to the right and ``v`` down from
the top-left corner of the image, so the centre of the top-left pixel is ``(0.5, 0.5)``. With
``pixel_convention="index"`` they are pixel indices as in OpenCV or a NumPy image
(``u = column``, ``v = row``), so the centre of the top-left pixel is ``(0, 0)``; 0.5 is then
added to both. The light is given in the model's world frame.

Every problem in the files raises :class:`~warpspec.SceneError` with a message that starts
``FILE:LINE: FIELD:``.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import warnings
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SceneError
from .scene import Light, Scene, SceneWarning

__all__ = [
    "CAMERA_MODELS",
    "ColmapCamera",
    "ColmapImage",
    "ColmapImport",
    "import_colmap",
    "load_colmap",
    "parse_light",
    "read_cameras",
    "read_highlights",
    "read_images",
    "read_points3d",
    "rotation_from_quaternion",
]

CAMERA_MODELS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
}
"""The supported COLMAP camera models and the names of their parameters, in file order."""

# Offset added to (u, v) to reach COLMAP's pixel convention.
_PIXEL_OFFSET = {"colmap": 0.0, "index": 0.5}
_HEADER_NAMES = ({"image", "image_name", "name", "file", "filename"}, {"u", "x"}, {"v", "y"})
_LIGHT_SPEC = re.compile(r"^\s*(directional|point)\s*[:=]\s*(.+)$", re.IGNORECASE)


@dataclass(frozen=True)
class ColmapCamera:
    """One line of ``cameras.txt``.

    Attributes:
        id: ``CAMERA_ID``.
        model: The model name, one of :data:`CAMERA_MODELS`.
        width: Image width in pixels.
        height: Image height in pixels.
        params: The model's parameters in file order.
        line: Line number in ``cameras.txt`` (for messages).
    """

    id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]
    line: int = 0

    @property
    def K(self) -> np.ndarray:
        """The 3x3 intrinsic matrix (distortion left out)."""
        p = self.params
        if self.model in ("PINHOLE", "OPENCV"):
            fx, fy, cx, cy = p[:4]
        else:
            fx = fy = p[0]
            cx, cy = p[1:3]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> dict[str, float]:
        """The distortion coefficients of the model by name (empty for the pinhole models)."""
        names = CAMERA_MODELS[self.model]
        first = 4 if self.model in ("PINHOLE", "OPENCV") else 3
        return dict(zip(names[first:], self.params[first:], strict=True))

    def distort(self, pixels: np.ndarray) -> np.ndarray:
        """Apply the model's lens distortion to ideal pixels, shape ``(n, 2)`` (COLMAP's rules)."""
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        K = self.K
        x = (pixels[:, 0] - K[0, 2]) / K[0, 0]
        y = (pixels[:, 1] - K[1, 2]) / K[1, 1]
        d = self.distortion
        r2 = x * x + y * y
        radial = d.get("k", 0.0) * r2 + d.get("k1", 0.0) * r2 + d.get("k2", 0.0) * r2 * r2
        p1, p2 = d.get("p1", 0.0), d.get("p2", 0.0)
        dx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = y * radial + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * y * y)
        return np.stack([K[0, 0] * (x + dx) + K[0, 2], K[1, 1] * (y + dy) + K[1, 2]], axis=1)


@dataclass(frozen=True)
class ColmapImage:
    """The first line of an image in ``images.txt``.

    Attributes:
        id: ``IMAGE_ID``.
        qvec: ``(QW, QX, QY, QZ)``, the world-to-camera rotation as a unit quaternion.
        tvec: ``(TX, TY, TZ)``, the world-to-camera translation.
        camera_id: ``CAMERA_ID`` of its intrinsics.
        name: ``NAME``, the image file name relative to COLMAP's image folder.
        line: Line number in ``images.txt`` (for messages).
    """

    id: int
    qvec: tuple[float, float, float, float]
    tvec: tuple[float, float, float]
    camera_id: int
    name: str
    line: int = 0

    @property
    def R(self) -> np.ndarray:
        """The world-to-camera rotation matrix."""
        return rotation_from_quaternion(self.qvec)

    @property
    def centre(self) -> np.ndarray:
        """The camera centre in world coordinates, ``-R^T t``."""
        return -self.R.T @ np.asarray(self.tvec)


@dataclass(frozen=True)
class ColmapImport:
    """A COLMAP model turned into a scene, with what maps it back to the model.

    Attributes:
        scene: The scene.
        image_names: The image ``NAME`` of each scene camera.
        image_ids: The ``IMAGE_ID`` of each scene camera.
        point_ids: The ``POINT3D_ID`` of each point constraint.
        highlight_lines: The line of the highlights file of each specularity.
    """

    scene: Scene
    image_names: tuple[str, ...]
    image_ids: tuple[int, ...]
    point_ids: tuple[int, ...]
    highlight_lines: tuple[int, ...]


# --------------------------------------------------------------------------------------------
# Small helpers


def _where(path: Path, line: int) -> str:
    return f"{path}:{line}"


def _fail(path: Path, line: int, field: str, message: str) -> SceneError:
    return SceneError(f"{_where(path, line)}: {field}: {message}")


def _short(text: str) -> str:
    text = " ".join(text.split())
    return repr(text if len(text) <= 40 else text[:37] + "...")


def _read_text(path: Path, what: str) -> str:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        hint = ""
        if path.with_suffix(".bin").exists():
            hint = (f"; the folder has the binary {path.stem}.bin: convert it with colmap "
                    "model_converter --output_type TXT")
        raise SceneError(f"{path}: no such file, expected {what}{hint}") from None
    except IsADirectoryError:
        raise SceneError(f"{path}: is a folder, expected {what}") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise _fail(path, line, "text", "not UTF-8 text") from None


def _lines(text: str) -> Iterator[tuple[int, str]]:
    """Number and content of each line that is not blank or a ``#`` comment."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            yield number, stripped


def _int(token: str, path: Path, line: int, field: str, *, low: int | None = None) -> int:
    try:
        value = int(token)
    except ValueError:
        raise _fail(path, line, field, f"expected an integer, got {_short(token)}") from None
    if low is not None and value < low:
        raise _fail(path, line, field, f"expected an integer >= {low}, got {value}")
    return value


def _float(token: str, path: Path, line: int, field: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise _fail(path, line, field, f"expected a number, got {_short(token)}") from None
    if not math.isfinite(value):
        raise _fail(path, line, field, f"expected a finite number, got {_short(token)}")
    return value


def rotation_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix of the quaternion ``(w, x, y, z)`` (Hamilton convention, as COLMAP).

    The quaternion is normalised first.

    Raises:
        SceneError: If the quaternion is zero or not finite.
    """
    q = np.asarray(q, dtype=np.float64).reshape(4)
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 0):
        raise SceneError(f"qvec: expected a non-zero quaternion, got {q.tolist()}")
    w, x, y, z = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# --------------------------------------------------------------------------------------------
# The three model files


def read_cameras(path: str | os.PathLike) -> dict[int, ColmapCamera]:
    """Read ``cameras.txt``.

    Returns:
        The cameras by ``CAMERA_ID``.

    Raises:
        SceneError: If the file is missing or a line is malformed (``FILE:LINE: FIELD: ...``).
    """
    path = Path(path)
    text = _read_text(path, "a COLMAP cameras.txt")
    cameras: dict[int, ColmapCamera] = {}
    for n, line in _lines(text):
        tokens = line.split()
        if len(tokens) < 4:
            raise _fail(path, n, "line", "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got "
                        f"{len(tokens)} fields")
        cam_id = _int(tokens[0], path, n, "CAMERA_ID")
        if cam_id in cameras:
            raise _fail(path, n, "CAMERA_ID", f"camera {cam_id} is defined twice (first on line "
                        f"{cameras[cam_id].line})")
        model = tokens[1].upper()
        if model not in CAMERA_MODELS:
            raise _fail(path, n, "MODEL", f"unsupported camera model {_short(tokens[1])}, expected "
                        f"one of {', '.join(CAMERA_MODELS)}; undistort the images with colmap "
                        "image_undistorter to get a PINHOLE model")
        width = _int(tokens[2], path, n, "WIDTH", low=1)
        height = _int(tokens[3], path, n, "HEIGHT", low=1)
        names = CAMERA_MODELS[model]
        if len(tokens) - 4 != len(names):
            raise _fail(path, n, "PARAMS", f"{model} takes {len(names)} parameters "
                        f"({', '.join(names)}), got {len(tokens) - 4}")
        params = tuple(_float(t, path, n, f"PARAMS.{name}")
                       for t, name in zip(tokens[4:], names, strict=True))
        for name, value in zip(names, params, strict=True):
            if name in ("f", "fx", "fy") and value <= 0:
                raise _fail(path, n, f"PARAMS.{name}", f"expected a positive focal length, got "
                            f"{value:g}")
        cameras[cam_id] = ColmapCamera(cam_id, model, width, height, params, n)
    return cameras


def read_images(path: str | os.PathLike) -> dict[int, ColmapImage]:
    """Read ``images.txt`` (two lines per image; the second, the 2-D points, may be empty).

    Returns:
        The images by ``IMAGE_ID``.

    Raises:
        SceneError: If the file is missing or a line is malformed (``FILE:LINE: FIELD: ...``).
    """
    path = Path(path)
    text = _read_text(path, "a COLMAP images.txt")
    images: dict[int, ColmapImage] = {}
    names: dict[str, int] = {}
    lines = text.splitlines()
    n = 0
    while n < len(lines):
        header = n + 1  # 1-based number of this image's first line
        line = lines[n].strip()
        n += 1
        if not line or line.startswith("#"):
            continue
        tokens = line.split(maxsplit=9)
        if len(tokens) < 10:
            raise _fail(path, header, "line", "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID "
                        f"NAME, got {len(tokens)} fields")
        image_id = _int(tokens[0], path, header, "IMAGE_ID")
        if image_id in images:
            raise _fail(path, header, "IMAGE_ID", f"image {image_id} is defined twice (first on "
                        f"line {images[image_id].line})")
        fields = ("QW", "QX", "QY", "QZ", "TX", "TY", "TZ")
        values = [_float(t, path, header, f) for t, f in zip(tokens[1:8], fields, strict=True)]
        if not math.hypot(*values[:4]) > 1e-12:
            raise _fail(path, header, "QW QX QY QZ", "expected a unit quaternion, got all zeros")
        camera_id = _int(tokens[8], path, header, "CAMERA_ID")
        name = tokens[9].strip()
        if name in names:
            raise _fail(path, header, "NAME", f"image {name!r} is listed twice (also as IMAGE_ID "
                        f"{names[name]})")
        names[name] = image_id
        # The second line: POINTS2D[] as (X, Y, POINT3D_ID); only its shape is checked.
        if n < len(lines):
            points2d = lines[n].split()
            n += 1
            if len(points2d) % 3:
                raise _fail(path, n, "POINTS2D", f"expected (X, Y, POINT3D_ID) triples, got "
                            f"{len(points2d)} numbers; each image takes two lines, the second of "
                            "which may be empty")
        images[image_id] = ColmapImage(image_id, tuple(values[:4]), tuple(values[4:]),
                                       camera_id, name, header)
    return images


def read_points3d(
    path: str | os.PathLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read ``points3D.txt``.

    Returns:
        ``POINT3D_ID`` (``(K,)`` int64), position (``(K, 3)``), reprojection ``ERROR``
        (``(K,)``, pixels) and track length (``(K,)``, the number of observations).

    Raises:
        SceneError: If the file is missing or a line is malformed (``FILE:LINE: FIELD: ...``).
    """
    path = Path(path)
    text = _read_text(path, "a COLMAP points3D.txt")
    ids: list[int] = []
    xyz: list[tuple[float, float, float]] = []
    errors: list[float] = []
    tracks: list[int] = []
    seen: dict[int, int] = {}
    for n, line in _lines(text):
        tokens = line.split()
        if len(tokens) < 8:
            raise _fail(path, n, "line", "expected POINT3D_ID X Y Z R G B ERROR TRACK[], got "
                        f"{len(tokens)} fields")
        point_id = _int(tokens[0], path, n, "POINT3D_ID")
        if point_id in seen:
            raise _fail(path, n, "POINT3D_ID", f"point {point_id} is defined twice (first on "
                        f"line {seen[point_id]})")
        seen[point_id] = n
        x = tuple(_float(t, path, n, f) for t, f in zip(tokens[1:4], "XYZ", strict=True))
        for t, f in zip(tokens[4:7], "RGB", strict=True):
            _int(t, path, n, f, low=0)
        try:
            error = float(tokens[7])
        except ValueError:
            raise _fail(path, n, "ERROR", f"expected a number, got {_short(tokens[7])}") from None
        if (len(tokens) - 8) % 2:
            raise _fail(path, n, "TRACK", f"expected (IMAGE_ID, POINT2D_IDX) pairs, got "
                        f"{len(tokens) - 8} numbers")
        ids.append(point_id)
        xyz.append(x)
        errors.append(error if math.isfinite(error) and error >= 0 else math.inf)
        tracks.append((len(tokens) - 8) // 2)
    return (np.array(ids, dtype=np.int64), np.array(xyz, dtype=np.float64).reshape(-1, 3),
            np.array(errors, dtype=np.float64), np.array(tracks, dtype=np.int64))


# --------------------------------------------------------------------------------------------
# Highlights and light


def _is_header(row: list[str]) -> bool:
    cells = [c.strip().lower() for c in row]
    return len(cells) == 3 and all(c in names for c, names in
                                   zip(cells, _HEADER_NAMES, strict=True))


def read_highlights(path: str | os.PathLike) -> list[tuple[int, str, float, float]]:
    """Read the highlights CSV: rows of ``image,u,v`` with an optional header row.

    Returns:
        ``(line, image name, u, v)`` per highlight, in file order, pixels as written.

    Raises:
        SceneError: If the file is missing or a row is malformed (``FILE:LINE: FIELD: ...``).
    """
    path = Path(path)
    text = _read_text(path, "a CSV of highlights (image,u,v rows)")
    rows: list[tuple[int, str, float, float]] = []
    lines = text.splitlines()
    first = True
    for n, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            row = next(csv.reader([line], skipinitialspace=True))
        except csv.Error as exc:
            raise _fail(path, n, "row", f"not valid CSV ({exc})") from None
        if first and _is_header(row):
            first = False
            continue
        first = False
        if len(row) != 3:
            raise _fail(path, n, "row", f"expected 3 columns image,u,v, got {len(row)}: "
                        f"{_short(line)}")
        name = row[0].strip()
        if not name:
            raise _fail(path, n, "image", "expected an image name, got an empty cell")
        u = _float(row[1].strip(), path, n, "u")
        v = _float(row[2].strip(), path, n, "v")
        rows.append((n, name, u, v))
    return rows


def parse_light(spec: str | Mapping | Light, *, field: str = "light") -> Light:
    """Read a light from a command-line spec, a JSON object (or its text) or a :class:`Light`.

    Specs: ``camera`` (a flash at each camera), ``directional:X,Y,Z`` (the direction from the
    surface toward the light), ``point:X,Y,Z`` (the light's position), or JSON such as
    ``{"type": "directional", "direction": [0, 0, 1]}``; always in the model's world frame.

    Raises:
        SceneError: If the spec is not a valid light; the message names ``field``.
    """
    if isinstance(spec, Light):
        return spec
    if isinstance(spec, Mapping):
        return Light.from_dict(spec, field=field)
    if not isinstance(spec, str):
        raise SceneError(f"{field}: expected a light spec or object, got {type(spec).__name__}")
    text = spec.strip()
    usage = ("expected 'camera', 'directional:X,Y,Z', 'point:X,Y,Z' or a JSON object like "
             '{"type": "directional", "direction": [X, Y, Z]}')
    if text.startswith("{"):
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SceneError(f"{field}: not valid JSON ({exc.msg} at column {exc.colno}); "
                             f"{usage}") from None
        return Light.from_dict(data, field=field)
    if text.lower() == "camera":
        return Light("camera")
    match = _LIGHT_SPEC.match(text)
    if not match:
        raise SceneError(f"{field}: {_short(text)} is not a light; {usage}")
    kind = match.group(1).lower()
    parts = [p for p in re.split(r"[,\s]+", match.group(2).strip()) if p]
    try:
        vector = [float(p) for p in parts]
    except ValueError:
        vector = []
    if len(vector) != 3 or not all(math.isfinite(x) for x in vector):
        raise SceneError(f"{field}: {kind} light needs 3 finite numbers X,Y,Z, got "
                         f"{_short(match.group(2))}")
    key = "direction" if kind == "directional" else "position"
    return Light.from_dict({"type": kind, key: vector}, field=field)


# --------------------------------------------------------------------------------------------
# The import


def _select_points(ids: np.ndarray, points: Any, path: Path) -> np.ndarray:
    """Indices of the chosen points, in file order."""
    if isinstance(points, str):
        if points == "all":
            return np.arange(len(ids))
        if points == "none":
            return np.zeros(0, dtype=np.int64)
        raise SceneError(f"points: expected 'all', 'none' or a collection of POINT3D_IDs, got "
                         f"{points!r}")
    if not isinstance(points, Collection):
        raise SceneError(f"points: expected 'all', 'none' or a collection of POINT3D_IDs, got "
                         f"{type(points).__name__}")
    wanted = []
    for p in points:
        if isinstance(p, bool) or not isinstance(p, int | np.integer):
            raise SceneError(f"points: expected integer POINT3D_IDs, got {p!r}")
        wanted.append(int(p))
    position = {int(i): k for k, i in enumerate(ids)}
    missing = [p for p in wanted if p not in position]
    if missing:
        raise SceneError(f"points: POINT3D_ID {missing[0]} is not in {path}")
    return np.array(sorted({position[p] for p in wanted}), dtype=np.int64)


def _best(chosen: np.ndarray, ids: np.ndarray, errors: np.ndarray, tracks: np.ndarray,
          max_points: int) -> np.ndarray:
    """Keep the ``max_points`` points of least reprojection error (longer tracks first on ties)."""
    if len(chosen) <= max_points:
        return chosen
    order = np.lexsort((ids[chosen], -tracks[chosen], errors[chosen]))
    return np.sort(chosen[order[:max_points]])


def _domain(domain: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate a ``(min, max)`` box given as two 3-vectors."""
    try:
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in domain)
    except (TypeError, ValueError):
        raise SceneError(f"domain: expected (min, max), two 3-vectors, got {domain!r}") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise SceneError(f"domain: max must exceed min on every axis, got min={lo.tolist()} "
                         f"max={hi.tolist()}")
    return lo, hi


def _highlight_line(message: str, lines: Sequence[int], csv_path: Path) -> str:
    match = re.search(r"specularities\[(\d+)\]", message)
    if match and int(match.group(1)) < len(lines):
        return f"{message} ({csv_path}:{lines[int(match.group(1))]})"
    return message


def import_colmap(
    model_dir: str | os.PathLike,
    highlights_csv: str | os.PathLike | None,
    *,
    light: str | Mapping | Light | None,
    points: str | Collection[int] = "all",
    max_points: int | None = None,
    domain: tuple[Sequence[float], Sequence[float]] | None = None,
    pixel_convention: str = "colmap",
) -> ColmapImport:
    """Turn a COLMAP text model and a CSV of highlights into a scene.

    Args:
        model_dir: The folder with ``cameras.txt``, ``images.txt`` and ``points3D.txt``.
        highlights_csv: The CSV of ``image,u,v`` highlights (``None``: no highlights).
        light: The light, in the model's world frame (see :func:`parse_light`); may be
            ``None`` only without highlights.
        points: Which 3D points become point constraints: ``"all"``, ``"none"``, or a
            collection of ``POINT3D_ID``.
        max_points: Keep at most this many of them, those of least reprojection error.
        domain: The box ``(min, max)`` to reconstruct in; points outside it are dropped (with a
            warning). Without it the box is derived from the points, so background points
            widen it.
        pixel_convention: ``"colmap"`` (the centre of the top-left pixel is ``(0.5, 0.5)``) or
            ``"index"`` (it is ``(0, 0)``); see the module's notes.

    Returns:
        The scene and the image and point ids behind it.

    Raises:
        SceneError: If a file is missing or malformed (``FILE:LINE: FIELD: ...``), a highlight
            names an unknown image or lies outside its image, or an option is invalid.
    """
    if not isinstance(model_dir, str | os.PathLike):
        raise SceneError(f"model_dir: expected a folder path, got {type(model_dir).__name__}")
    folder = Path(model_dir)
    if not folder.is_dir():
        what = "not a folder" if folder.exists() else "no such folder"
        raise SceneError(f"{folder}: {what}, expected a COLMAP text model (cameras.txt, "
                         "images.txt, points3D.txt)")
    if pixel_convention not in _PIXEL_OFFSET:
        raise SceneError(f"pixel_convention: expected 'colmap' or 'index', got "
                         f"{pixel_convention!r}")
    if max_points is not None and (isinstance(max_points, bool)
                                   or not isinstance(max_points, int | np.integer)
                                   or max_points < 0):
        raise SceneError(f"max_points: expected a non-negative integer, got {max_points!r}")
    if isinstance(points, str) and points not in ("all", "none"):
        raise SceneError(f"points: expected 'all', 'none' or a collection of POINT3D_IDs, got "
                         f"{points!r}")
    the_light = None if light is None else parse_light(light)
    box = None if domain is None else _domain(domain)

    cameras_path = folder / "cameras.txt"
    images_path = folder / "images.txt"
    points_path = folder / "points3D.txt"
    cameras = read_cameras(cameras_path)
    images = read_images(images_path)
    if not images:
        raise SceneError(f"{images_path}: no registered images, expected at least one")
    for image in images.values():
        if image.camera_id not in cameras:
            raise _fail(images_path, image.line, "CAMERA_ID",
                        f"camera {image.camera_id} of image {image.name!r} is not in "
                        f"{cameras_path}")

    order = sorted(images)
    index = {image_id: k for k, image_id in enumerate(order)}
    matrices = np.empty((len(order), 3, 4))
    for k, image_id in enumerate(order):
        image = images[image_id]
        try:
            R = image.R
        except SceneError as exc:
            raise _fail(images_path, image.line, "QW QX QY QZ", str(exc)) from None
        Rt = np.concatenate([R, np.asarray(image.tvec)[:, None]], axis=1)
        with np.errstate(all="ignore"):
            matrices[k] = cameras[image.camera_id].K @ Rt
        if not np.all(np.isfinite(matrices[k])):
            raise _fail(images_path, image.line, "TX TY TZ", "the projection matrix K [R | t] "
                        "overflows; the translation is too large")

    # Highlights.
    by_name = {image.name: image_id for image_id, image in images.items()}
    by_base: dict[str, list[int]] = {}
    for image_id, image in images.items():
        by_base.setdefault(Path(image.name).name, []).append(image_id)
    rows = [] if highlights_csv is None else read_highlights(highlights_csv)
    csv_path = None if highlights_csv is None else Path(highlights_csv)
    offset = _PIXEL_OFFSET[pixel_convention]
    spec_camera, spec_pixel, lines = [], [], []
    for line, name, u, v in rows:
        image_id = by_name.get(name)
        if image_id is None:
            candidates = by_base.get(Path(name).name, [])
            if len(candidates) == 1:
                image_id = candidates[0]
            elif candidates:
                raise _fail(csv_path, line, "image", f"{name!r} matches {len(candidates)} "
                            "images by base name; give the NAME as in images.txt")
            else:
                shown = ", ".join(repr(images[i].name) for i in order[:3])
                raise _fail(csv_path, line, "image", f"{name!r} is not an image of {images_path}"
                            f" (it has {len(order)}: {shown}{', ...' if len(order) > 3 else ''})")
        camera = cameras[images[image_id].camera_id]
        pu, pv = u + offset, v + offset
        if not (0.0 <= pu <= camera.width and 0.0 <= pv <= camera.height):
            raise _fail(csv_path, line, "u, v", f"({u:g}, {v:g}) lies outside the "
                        f"{camera.width}x{camera.height} image {images[image_id].name!r} "
                        f"({pixel_convention} convention); are u and v swapped?")
        spec_camera.append(index[image_id])
        spec_pixel.append((pu, pv))
        lines.append(line)
    if spec_camera and the_light is None:
        raise SceneError("light: missing; the highlights need a light: 'camera', "
                         "'directional:X,Y,Z' or 'point:X,Y,Z'")
    _warn_distortion(cameras, images, order, spec_camera, spec_pixel, cameras_path)

    # Points.
    if isinstance(points, str) and points == "none":
        ids = np.zeros(0, dtype=np.int64)
        xyz = np.zeros((0, 3))
        chosen = np.zeros(0, dtype=np.int64)
    else:
        ids, xyz, errors, tracks = read_points3d(points_path)
        chosen = _select_points(ids, points, points_path)
        if box is not None:
            inside = np.all((xyz[chosen] >= box[0]) & (xyz[chosen] <= box[1]), axis=1)
            if not inside.all():
                warnings.warn(f"{points_path}: dropped {int((~inside).sum())} of {len(chosen)} "
                              "points outside the domain", SceneWarning, stacklevel=2)
            chosen = chosen[inside]
        if max_points is not None:
            chosen = _best(chosen, ids, errors, tracks, int(max_points))
    try:
        scene = Scene(
            matrices,
            np.array(spec_camera, dtype=np.int64),
            np.array(spec_pixel, dtype=np.float64).reshape(-1, 2),
            xyz[chosen],
            light=the_light,
            domain=box,
        )
    except SceneError as exc:
        raise SceneError(_highlight_line(str(exc), lines, csv_path)) from None
    return ColmapImport(
        scene=scene,
        image_names=tuple(images[i].name for i in order),
        image_ids=tuple(order),
        point_ids=tuple(int(i) for i in ids[chosen]),
        highlight_lines=tuple(lines),
    )


def _warn_distortion(cameras: Mapping[int, ColmapCamera], images: Mapping[int, ColmapImage],
                     order: Sequence[int], spec_camera: Sequence[int],
                     spec_pixel: Sequence[tuple[float, float]], cameras_path: Path) -> None:
    """Warn, per camera with highlights, that its lens distortion is ignored and how much."""
    shifts: dict[int, float] = {}
    for k, pixel in zip(spec_camera, spec_pixel, strict=True):
        camera = cameras[images[order[k]].camera_id]
        if any(v != 0.0 for v in camera.distortion.values()):
            moved = float(np.linalg.norm(camera.distort(np.array([pixel]))[0] - pixel))
            shifts[camera.id] = max(shifts.get(camera.id, 0.0), moved)
    for cam_id, shift in sorted(shifts.items()):
        camera = cameras[cam_id]
        coeffs = ", ".join(f"{k}={v:.3g}" for k, v in camera.distortion.items())
        warnings.warn(
            f"{cameras_path}:{camera.line}: camera {cam_id} is {camera.model} ({coeffs}); its "
            f"lens distortion is ignored, which moves its highlights by up to {shift:.2f} px; "
            "undistort the images with colmap image_undistorter for a PINHOLE model",
            SceneWarning, stacklevel=3,
        )


def load_colmap(
    model_dir: str | os.PathLike,
    highlights_csv: str | os.PathLike | None,
    *,
    light: str | Mapping | Light | None,
    points: str | Collection[int] = "all",
    max_points: int | None = None,
    domain: tuple[Sequence[float], Sequence[float]] | None = None,
    pixel_convention: str = "colmap",
) -> Scene:
    """Load a COLMAP text model and a CSV of highlights as a :class:`~warpspec.Scene`.

    The arguments are those of :func:`import_colmap`, which also returns the image and point
    ids behind the scene.

    Raises:
        SceneError: If a file is missing or malformed (``FILE:LINE: FIELD: ...``) or an option
            is invalid.
    """
    return import_colmap(model_dir, highlights_csv, light=light, points=points,
                         max_points=max_points, domain=domain,
                         pixel_convention=pixel_convention).scene
