"""Import a COLMAP model and a CSV of highlights as a warpspec :class:`~warpspec.Scene`.

COLMAP (https://colmap.github.io) is the structure-from-motion tool most people use to get
cameras and sparse 3D points from photographs. Its model is three files in one folder, as
text or binary (``cameras.bin``, ``images.bin``, ``points3D.bin``, read with the same checks);
a ``sparse/`` folder holding ``0/`` is accepted too. The text files are:

- ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``, one camera (intrinsics) a line;
- ``images.txt``: two lines per registered image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID
  NAME`` and then its ``POINTS2D[]`` as ``(X, Y, POINT3D_ID)`` triples (the line may be empty);
  the quaternion and translation map world to camera coordinates, ``x_cam = R x_world + t``;
- ``points3D.txt``: ``POINT3D_ID X Y Z R G B ERROR TRACK[]`` with the track as
  ``(IMAGE_ID, POINT2D_IDX)`` pairs.

Lines starting with ``#`` are comments. Every registered image becomes a warpspec camera
``P = K [R | t]``, in increasing ``IMAGE_ID`` order (``ColmapImport.image_names`` gives each
camera's image). By default the point constraints are the object's points only, those near
where the highlight rays meet and off the background's large planes, and the domain is sized
from them and the rays (:func:`select_object_points`, :func:`auto_domain`).

Camera models: ``SIMPLE_PINHOLE``, ``PINHOLE``, ``SIMPLE_RADIAL``, ``RADIAL``, ``OPENCV`` and
``FULL_OPENCV``; the highlights of a camera with lens distortion are undistorted (Newton's
method on COLMAP's distortion). Fisheye models are refused, naming the camera.

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
import struct
import warnings
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, SceneError
from .scene import Light, Scene, SceneWarning, ray_box_span

__all__ = [
    "CAMERA_MODELS",
    "FISHEYE_MODELS",
    "auto_domain",
    "find_model",
    "quaternion_from_rotation",
    "ray_region",
    "read_cameras_bin",
    "read_images_bin",
    "read_model",
    "read_points3d_bin",
    "select_object_points",
    "write_model",
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
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
"""The supported COLMAP camera models and the names of their parameters, in file order."""

FISHEYE_MODELS: dict[str, int] = {
    "OPENCV_FISHEYE": 8,
    "FOV": 5,
    "SIMPLE_RADIAL_FISHEYE": 4,
    "RADIAL_FISHEYE": 5,
    "THIN_PRISM_FISHEYE": 12,
    "RAD_TAN_THIN_PRISM_FISHEYE": 16,
}
"""COLMAP's fisheye models (and their parameter counts), which are refused."""

# COLMAP's numeric model ids, as in the binary cameras.bin.
MODEL_IDS: dict[int, str] = {
    0: "SIMPLE_PINHOLE", 1: "PINHOLE", 2: "SIMPLE_RADIAL", 3: "RADIAL", 4: "OPENCV",
    5: "OPENCV_FISHEYE", 6: "FULL_OPENCV", 7: "FOV", 8: "SIMPLE_RADIAL_FISHEYE",
    9: "RADIAL_FISHEYE", 10: "THIN_PRISM_FISHEYE", 11: "RAD_TAN_THIN_PRISM_FISHEYE",
}
_TWO_FOCALS = ("PINHOLE", "OPENCV", "FULL_OPENCV")
_UNDISTORTER_HINT = ("undistort the images with colmap image_undistorter to get a PINHOLE "
                     "model")

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
        if self.model in _TWO_FOCALS:
            fx, fy, cx, cy = p[:4]
        else:
            fx = fy = p[0]
            cx, cy = p[1:3]
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> dict[str, float]:
        """The distortion coefficients of the model by name (empty for the pinhole models)."""
        names = CAMERA_MODELS[self.model]
        first = 4 if self.model in _TWO_FOCALS else 3
        return dict(zip(names[first:], self.params[first:], strict=True))

    def _distort_normalised(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = self.distortion
        r2 = x * x + y * y
        if self.model == "FULL_OPENCV":
            num = 1 + r2 * (d["k1"] + r2 * (d["k2"] + r2 * d["k3"]))
            den = 1 + r2 * (d["k4"] + r2 * (d["k5"] + r2 * d["k6"]))
            radial = num / den - 1
        else:
            radial = d.get("k", 0.0) * r2 + d.get("k1", 0.0) * r2 + d.get("k2", 0.0) * r2 * r2
        p1, p2 = d.get("p1", 0.0), d.get("p2", 0.0)
        dx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = y * radial + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * y * y)
        return x + dx, y + dy

    def distort(self, pixels: np.ndarray) -> np.ndarray:
        """Apply the model's lens distortion to ideal pixels, shape ``(n, 2)`` (COLMAP's rules)."""
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        K = self.K
        x = (pixels[:, 0] - K[0, 2]) / K[0, 0]
        y = (pixels[:, 1] - K[1, 2]) / K[1, 1]
        xd, yd = self._distort_normalised(x, y)
        return np.stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)

    def undistort(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal pixels whose distortion gives ``pixels`` ``(n, 2)``: Newton's method.

        Returns:
            The undistorted pixels ``(n, 2)`` and whether each converged (to 1e-9 pixel).
        """
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if not any(v != 0.0 for v in self.distortion.values()):
            return pixels.copy(), np.ones(len(pixels), dtype=bool)
        K = self.K
        xd = (pixels[:, 0] - K[0, 2]) / K[0, 0]
        yd = (pixels[:, 1] - K[1, 2]) / K[1, 1]
        x, y = xd.copy(), yd.copy()
        step = 1e-7
        with np.errstate(all="ignore"):
            for _ in range(100):
                fx, fy = self._distort_normalised(x, y)
                rx, ry = fx - xd, fy - yd
                ax, ay = self._distort_normalised(x + step, y)
                bx, by = self._distort_normalised(x, y + step)
                j11, j21 = (ax - fx) / step, (ay - fy) / step
                j12, j22 = (bx - fx) / step, (by - fy) / step
                det = j11 * j22 - j12 * j21
                dx = (j22 * rx - j12 * ry) / det
                dy = (j11 * ry - j21 * rx) / det
                x, y = x - dx, y - dy
                if np.all(np.abs(dx) + np.abs(dy) < 1e-14):
                    break
            fx, fy = self._distort_normalised(x, y)
            err = np.hypot((fx - xd) * K[0, 0], (fy - yd) * K[1, 1])
        ok = np.isfinite(err) & (err < 1e-9) & np.isfinite(x) & np.isfinite(y)
        out = np.stack([K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2]], axis=1)
        return out, ok


@dataclass(frozen=True)
class ColmapImage:
    """The first line of an image in ``images.txt``.

    Attributes:
        id: ``IMAGE_ID``.
        qvec: ``(QW, QX, QY, QZ)``, the world-to-camera rotation as a unit quaternion.
        tvec: ``(TX, TY, TZ)``, the world-to-camera translation.
        camera_id: ``CAMERA_ID`` of its intrinsics.
        name: ``NAME``, the image file name relative to COLMAP's image folder.
        line: Line number in ``images.txt`` (for messages), or record number in ``images.bin``.
        points2d: Its ``POINTS2D[]`` as ``(n, 3)`` rows ``X, Y, POINT3D_ID`` (-1: untracked).
    """

    id: int
    qvec: tuple[float, float, float, float]
    tvec: tuple[float, float, float]
    camera_id: int
    name: str
    line: int = 0
    points2d: np.ndarray | None = field(default=None, compare=False, repr=False)

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
        model_dir: The folder the model was read from (``sparse/0`` when given ``sparse``).
        model_format: ``"text"`` or ``"binary"``.
    """

    scene: Scene
    image_names: tuple[str, ...]
    image_ids: tuple[int, ...]
    point_ids: tuple[int, ...]
    highlight_lines: tuple[int, ...]
    model_dir: Path | None = None
    model_format: str = "text"


# --------------------------------------------------------------------------------------------
# Small helpers


def _where(path: Path, line: int | str) -> str:
    return f"{path}:{line}" if isinstance(line, int) else f"{path}, {line}"


def _fail(path: Path, line: int | str, field: str, message: str) -> SceneError:
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


def _check_model(model: str, shown: str, camera: Any, path: Path, where: int | str) -> None:
    """Refuse a camera model that is not one of :data:`CAMERA_MODELS`, naming the camera."""
    if model in CAMERA_MODELS:
        return
    if model in FISHEYE_MODELS:
        why = "a fisheye model, which warpspec does not handle"
    else:
        why = f"not a COLMAP camera model warpspec knows ({', '.join(CAMERA_MODELS)})"
    raise _fail(path, where, "MODEL", f"camera {camera} is {_short(shown)}, {why}; "
                f"{_UNDISTORTER_HINT}")


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
        _check_model(model, tokens[1], tokens[0], path, n)
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
        # The second line: POINTS2D[] as (X, Y, POINT3D_ID).
        obs = np.zeros((0, 3))
        if n < len(lines):
            points2d = lines[n].split()
            n += 1
            if len(points2d) % 3:
                raise _fail(path, n, "POINTS2D", f"expected (X, Y, POINT3D_ID) triples, got "
                            f"{len(points2d)} numbers; each image takes two lines, the second of "
                            "which may be empty")
            try:
                obs = np.array(points2d, dtype=np.float64).reshape(-1, 3)
            except ValueError:
                obs = np.zeros((0, 3))  # unreadable observations: the import does not need them
            if not np.all(np.isfinite(obs)):
                obs = obs[np.all(np.isfinite(obs), axis=1)]
        images[image_id] = ColmapImage(image_id, tuple(values[:4]), tuple(values[4:]),
                                       camera_id, name, header, obs)
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
# Binary models (cameras.bin, images.bin, points3D.bin), as COLMAP writes them


class _Binary:
    """A little-endian reader over a binary model file that names where it fails."""

    def __init__(self, path: Path, what: str) -> None:
        self.path = path
        try:
            self.data = path.read_bytes()
        except FileNotFoundError:
            raise SceneError(f"{path}: no such file, expected {what}") from None
        except IsADirectoryError:
            raise SceneError(f"{path}: is a folder, expected {what}") from None
        except OSError as exc:
            raise SceneError(f"{path}: cannot read it ({exc.strerror or exc})") from None
        self.pos = 0
        self.record = 0

    def where(self) -> str:
        return f"record {self.record} (byte {self.pos})" if self.record else f"byte {self.pos}"

    def fail(self, field: str, message: str) -> SceneError:
        return _fail(self.path, self.where(), field, message)

    def take(self, fmt: str, field: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        if self.pos + size > len(self.data):
            raise self.fail(field, f"the file ends early ({len(self.data)} bytes); is it a "
                            "complete COLMAP binary model?")
        values = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return values

    def array(self, dtype: np.dtype, count: int, field: str) -> np.ndarray:
        size = np.dtype(dtype).itemsize * count
        if count < 0 or self.pos + size > len(self.data):
            raise self.fail(field, f"{count} entries do not fit in the file's "
                            f"{len(self.data)} bytes; is it a complete COLMAP binary model?")
        out = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.pos)
        self.pos += size
        return out

    def count(self, field: str) -> int:
        (n,) = self.take("Q", field)
        if n > len(self.data):
            raise self.fail(field, f"{n} records cannot fit in {len(self.data)} bytes")
        return int(n)

    def finite(self, values: Sequence[float], names: Sequence[str]) -> None:
        for v, name in zip(values, names, strict=True):
            if not math.isfinite(v):
                raise self.fail(name, f"expected a finite number, got {v!r}")

    def end(self) -> None:
        self.record = 0
        if self.pos != len(self.data):
            raise self.fail("end", f"{len(self.data) - self.pos} bytes left after the last "
                            "record; is it a COLMAP binary model?")


def read_cameras_bin(path: str | os.PathLike) -> dict[int, ColmapCamera]:
    """Read a binary ``cameras.bin`` (same result as :func:`read_cameras` on its text twin).

    Raises:
        SceneError: If the file is missing, truncated or holds a model warpspec cannot use
            (``FILE, record N (byte B): FIELD: ...``).
    """
    f = _Binary(Path(path), "a COLMAP cameras.bin")
    cameras: dict[int, ColmapCamera] = {}
    for k in range(f.count("number of cameras")):
        f.record = k + 1
        cam_id, model_id, width, height = f.take("iiQQ", "camera")
        model = MODEL_IDS.get(model_id, f"model id {model_id}")
        if cam_id in cameras:
            raise f.fail("CAMERA_ID", f"camera {cam_id} is defined twice")
        _check_model(model, model, cam_id, f.path, f.where())
        if width < 1 or height < 1:
            raise f.fail("WIDTH HEIGHT", f"expected a positive size, got {width}x{height}")
        names = CAMERA_MODELS[model]
        params = tuple(float(v) for v in f.take("d" * len(names), "PARAMS"))
        f.finite(params, [f"PARAMS.{n}" for n in names])
        for name, value in zip(names, params, strict=True):
            if name in ("f", "fx", "fy") and value <= 0:
                raise f.fail(f"PARAMS.{name}", f"expected a positive focal length, got {value:g}")
        cameras[cam_id] = ColmapCamera(cam_id, model, int(width), int(height), params, k + 1)
    f.end()
    return cameras


def read_images_bin(path: str | os.PathLike) -> dict[int, ColmapImage]:
    """Read a binary ``images.bin`` (same result as :func:`read_images` on its text twin).

    Raises:
        SceneError: If the file is missing or truncated (``FILE, record N (byte B): ...``).
    """
    f = _Binary(Path(path), "a COLMAP images.bin")
    images: dict[int, ColmapImage] = {}
    names: dict[str, int] = {}
    for k in range(f.count("number of images")):
        f.record = k + 1
        (image_id,) = f.take("I", "IMAGE_ID")
        values = f.take("7d", "QW QX QY QZ TX TY TZ")
        f.finite(values, ("QW", "QX", "QY", "QZ", "TX", "TY", "TZ"))
        if not math.hypot(*values[:4]) > 1e-12:
            raise f.fail("QW QX QY QZ", "expected a unit quaternion, got all zeros")
        (camera_id,) = f.take("I", "CAMERA_ID")
        end = f.data.find(b"\0", f.pos)
        if end < 0:
            raise f.fail("NAME", "the image name has no end; is it a complete binary model?")
        try:
            name = f.data[f.pos:end].decode("utf-8")
        except UnicodeDecodeError:
            raise f.fail("NAME", "the image name is not UTF-8") from None
        f.pos = end + 1
        if image_id in images:
            raise f.fail("IMAGE_ID", f"image {image_id} is defined twice")
        if name in names:
            raise f.fail("NAME", f"image {name!r} is listed twice (also as IMAGE_ID "
                         f"{names[name]})")
        names[name] = image_id
        n = f.count("POINTS2D")
        raw = f.array(np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")]), n, "POINTS2D")
        obs = np.column_stack([raw["x"], raw["y"], raw["id"].astype(np.float64)])
        obs = obs[np.all(np.isfinite(obs), axis=1)]
        images[image_id] = ColmapImage(int(image_id), tuple(values[:4]), tuple(values[4:]),
                                       int(camera_id), name, k + 1, obs)
    f.end()
    return images


def read_points3d_bin(
    path: str | os.PathLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read a binary ``points3D.bin``; returns what :func:`read_points3d` returns.

    Raises:
        SceneError: If the file is missing or truncated (``FILE, record N (byte B): ...``).
    """
    f = _Binary(Path(path), "a COLMAP points3D.bin")
    ids, xyz, errors, tracks = [], [], [], []
    seen: set[int] = set()
    for k in range(f.count("number of points")):
        f.record = k + 1
        (point_id,) = f.take("Q", "POINT3D_ID")
        x = f.take("3d", "X Y Z")
        f.finite(x, "XYZ")
        f.take("3B", "R G B")
        (error,) = f.take("d", "ERROR")
        length = f.count("TRACK")
        f.array(np.dtype("<i4"), 2 * length, "TRACK")
        if point_id in seen:
            raise f.fail("POINT3D_ID", f"point {point_id} is defined twice")
        seen.add(point_id)
        ids.append(point_id)
        xyz.append(x)
        errors.append(error if math.isfinite(error) and error >= 0 else math.inf)
        tracks.append(length)
    f.end()
    return (np.array(ids, dtype=np.int64), np.array(xyz, dtype=np.float64).reshape(-1, 3),
            np.array(errors, dtype=np.float64), np.array(tracks, dtype=np.int64))


def find_model(folder: str | os.PathLike) -> tuple[Path, str]:
    """The folder and format (``"text"`` or ``"binary"``) of the COLMAP model in ``folder``.

    ``folder`` may be the model itself or a ``sparse/`` folder holding ``0/`` (COLMAP's
    layout; the first model, ``0``, is taken). When both a text and a binary model are there,
    the text one is read (it is the one a person may have edited).

    Raises:
        SceneError: If there is no model there, naming what was looked for.
    """
    if not isinstance(folder, str | os.PathLike):
        raise SceneError(f"model_dir: expected a folder path, got {type(folder).__name__}")
    root = Path(folder)
    if not root.is_dir():
        what = "not a folder" if root.exists() else "no such folder"
        raise SceneError(f"{root}: {what}, expected a COLMAP model (cameras, images and "
                         "points3D as .txt or .bin)")
    for candidate in (root, root / "0"):
        if (candidate / "cameras.txt").exists() or (candidate / "images.txt").exists():
            return candidate, "text"
        if (candidate / "cameras.bin").exists() or (candidate / "images.bin").exists():
            return candidate, "binary"
    subs = sorted(p.name for p in root.iterdir() if p.is_dir())
    hint = f" (it holds the folders {', '.join(subs[:5])})" if subs else ""
    raise SceneError(f"{root}: no COLMAP model here: expected cameras.txt or cameras.bin, "
                     f"here or in {root / '0'}{hint}")


def read_model(folder: str | os.PathLike, *, points: bool = True) -> tuple[
        dict[int, ColmapCamera], dict[int, ColmapImage],
        tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None, Path, str]:
    """Read a whole COLMAP model, text or binary (see :func:`find_model`).

    Args:
        folder: The model folder, or a ``sparse/`` folder holding ``0/``.
        points: Whether to read the 3D points too.

    Returns:
        Cameras, images, the points (``ids, xyz, errors, track lengths``, or ``None``), the
        model's folder and its format.
    """
    where, kind = find_model(folder)
    if kind == "text":
        cameras = read_cameras(where / "cameras.txt")
        images = read_images(where / "images.txt")
        pts = read_points3d(where / "points3D.txt") if points else None
    else:
        cameras = read_cameras_bin(where / "cameras.bin")
        images = read_images_bin(where / "images.bin")
        pts = read_points3d_bin(where / "points3D.bin") if points else None
    return cameras, images, pts, where, kind


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """The unit quaternion ``(w, x, y, z)``, ``w >= 0``, of a rotation matrix (COLMAP's)."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    K = np.array([
        [R[0, 0] - R[1, 1] - R[2, 2], R[1, 0] + R[0, 1], R[2, 0] + R[0, 2], R[2, 1] - R[1, 2]],
        [R[1, 0] + R[0, 1], R[1, 1] - R[0, 0] - R[2, 2], R[2, 1] + R[1, 2], R[0, 2] - R[2, 0]],
        [R[2, 0] + R[0, 2], R[2, 1] + R[1, 2], R[2, 2] - R[0, 0] - R[1, 1], R[1, 0] - R[0, 1]],
        [R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1], R[0, 0] + R[1, 1] + R[2, 2]],
    ]) / 3.0
    w, v = np.linalg.eigh(K)
    x, y, z, qw = v[:, int(np.argmax(w))]
    q = np.array([qw, x, y, z])
    return q if q[0] >= 0 else -q


def write_model(
    folder: str | os.PathLike,
    cameras: Mapping[int, ColmapCamera],
    images: Sequence[ColmapImage],
    observations: Sequence[np.ndarray],
    point_ids: np.ndarray,
    xyz: np.ndarray,
    colours: np.ndarray,
    errors: np.ndarray,
    tracks: Sequence[Sequence[tuple[int, int]]],
    *,
    text: bool = True,
    binary: bool = True,
) -> None:
    """Write a COLMAP model as text and/or binary files in ``folder``.

    Args:
        folder: The model folder (must exist).
        cameras: Cameras by ``CAMERA_ID``.
        images: The images.
        observations: Per image, ``(n, 3)`` rows ``X, Y, POINT3D_ID``.
        point_ids: ``POINT3D_ID`` per point ``(K,)``.
        xyz: Positions ``(K, 3)``.
        colours: RGB ``(K, 3)`` in 0..255.
        errors: Reprojection errors ``(K,)``.
        tracks: Per point, its ``(IMAGE_ID, POINT2D_IDX)`` pairs.
        text: Write ``cameras.txt``, ``images.txt``, ``points3D.txt``.
        binary: Write ``cameras.bin``, ``images.bin``, ``points3D.bin``.
    """
    out = Path(folder)
    ids_of = {name: k for k, name in MODEL_IDS.items()}
    if text:
        lines = ["# Camera list with one line of data per camera:",
                 "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
        for c in cameras.values():
            lines.append(f"{c.id} {c.model} {c.width} {c.height} "
                         + " ".join(repr(float(p)) for p in c.params))
        (out / "cameras.txt").write_text("\n".join(lines) + "\n")
        lines = ["# Image list with two lines of data per image:",
                 "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
                 "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
        for im, obs in zip(images, observations, strict=True):
            pose = " ".join(repr(float(v)) for v in (*im.qvec, *im.tvec))
            lines.append(f"{im.id} {pose} {im.camera_id} {im.name}")
            lines.append(" ".join(f"{float(x)!r} {float(y)!r} {int(i)}" for x, y, i in obs))
        (out / "images.txt").write_text("\n".join(lines) + "\n")
        lines = ["# 3D point list with one line of data per point:",
                 "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"]
        for pid, p, rgb, e, track in zip(point_ids, xyz, colours, errors, tracks, strict=True):
            lines.append(f"{int(pid)} {' '.join(repr(float(v)) for v in p)} "
                         f"{' '.join(str(int(c)) for c in rgb)} {float(e)!r} "
                         + " ".join(f"{i} {j}" for i, j in track))
        (out / "points3D.txt").write_text("\n".join(lines) + "\n")
    if binary:
        parts = [struct.pack("<Q", len(cameras))]
        for c in cameras.values():
            parts.append(struct.pack("<iiQQ", c.id, ids_of[c.model], c.width, c.height))
            parts.append(struct.pack(f"<{len(c.params)}d", *c.params))
        (out / "cameras.bin").write_bytes(b"".join(parts))
        parts = [struct.pack("<Q", len(images))]
        for im, obs in zip(images, observations, strict=True):
            parts.append(struct.pack("<I7dI", im.id, *im.qvec, *im.tvec, im.camera_id))
            parts.append(im.name.encode("utf-8") + b"\0")
            parts.append(struct.pack("<Q", len(obs)))
            for x, y, i in obs:
                parts.append(struct.pack("<ddq", x, y, int(i)))
        (out / "images.bin").write_bytes(b"".join(parts))
        parts = [struct.pack("<Q", len(point_ids))]
        for pid, p, rgb, e, track in zip(point_ids, xyz, colours, errors, tracks, strict=True):
            parts.append(struct.pack("<Q3d3BdQ", int(pid), *map(float, p),
                                     *(int(c) for c in rgb), float(e), len(track)))
            parts.append(b"".join(struct.pack("<ii", i, j) for i, j in track))
        (out / "points3D.bin").write_bytes(b"".join(parts))


# --------------------------------------------------------------------------------------------
# Highlights and light


def _is_header(row: list[str]) -> bool:
    cells = [c.strip().lower() for c in row]
    return len(cells) >= 3 and all(c in names for c, names in
                                   zip(cells[:3], _HEADER_NAMES, strict=True))


def read_highlights(path: str | os.PathLike) -> list[tuple[int, str, float, float]]:
    """Read the highlights CSV: rows of ``image,u,v`` with an optional header row.

    Columns after the third (``warpspec detect`` writes ``peak,size,score``) are ignored.

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
        if len(row) < 3:
            raise _fail(path, n, "row", f"expected the columns image,u,v (more may follow), got "
                        f"{len(row)}: {_short(line)}")
        name = row[0].strip()
        if not name:
            raise _fail(path, n, "image", "expected an image name, got an empty cell")
        u = _float(row[1].strip(), path, n, "u")
        v = _float(row[2].strip(), path, n, "v")
        rows.append((n, name, u, v))
    if not rows:
        raise InputError(f"{path}: holds no highlight (no image,u,v row): there is nothing to "
                         "reconstruct from; run 'warpspec detect' on the photographs, or check "
                         "its thresholds")
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


def _closest_approaches(origins: np.ndarray, dirs: np.ndarray, cams: np.ndarray,
                        limit: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Midpoints and gaps of the closest approaches of ray pairs from different cameras.

    Only pairs that meet in front of both cameras and are not near parallel count; at most
    ``limit`` rays (evenly spread) are paired.
    """
    if len(origins) > limit:
        keep = np.linspace(0, len(origins) - 1, limit).astype(np.int64)
        origins, dirs, cams = origins[keep], dirs[keep], cams[keep]
    i, j = np.triu_indices(len(origins), k=1)
    ok = cams[i] != cams[j]
    i, j = i[ok], j[ok]
    w = origins[i] - origins[j]
    b = np.einsum("ij,ij->i", dirs[i], dirs[j])
    d = np.einsum("ij,ij->i", dirs[i], w)
    e = np.einsum("ij,ij->i", dirs[j], w)
    den = 1.0 - b * b
    good = den > 1e-6
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (b * e - d) / den
        t = (e - b * d) / den
    good &= (s > 0) & (t > 0)
    p = origins[i] + s[:, None] * dirs[i]
    q = origins[j] + t[:, None] * dirs[j]
    return ((p + q) / 2)[good], np.linalg.norm(p - q, axis=1)[good]


def ray_region(origins: np.ndarray, dirs: np.ndarray, cams: np.ndarray
               ) -> tuple[np.ndarray, float] | None:
    """Where the highlight rays pass most tightly: a robust centre and radius.

    The closest approaches of ray pairs from different cameras are taken, the tighter half
    (gap at most the median) is kept, and the centre is the coordinate-wise median of their
    midpoints; the radius is the 80th percentile of those midpoints' distances to the centre.

    Returns:
        ``(centre, radius)``, or ``None`` when fewer than two cameras have rays that meet.
    """
    mids, gaps = _closest_approaches(np.asarray(origins, float), np.asarray(dirs, float),
                                     np.asarray(cams))
    if len(mids) == 0:
        return None
    mids = mids[gaps <= np.median(gaps)]
    centre = np.median(mids, axis=0)
    radius = float(np.percentile(np.linalg.norm(mids - centre, axis=1), 80))
    return centre, radius


def _frame_radius(centre: np.ndarray, matrices: np.ndarray, sizes: np.ndarray) -> float:
    """Half the smaller side of a typical image, in world units at the object's distance.

    The focal lengths come from ``M M^T = K K^T`` (``P = [M | p4]``, ``M = K R``, no skew):
    ``fx^2 = A00 / A22 - (A02 / A22)^2`` and likewise ``fy``.
    """
    radii = []
    for P, (w, h) in zip(matrices, sizes, strict=True):
        M = P[:, :3]
        c = -np.linalg.solve(M, P[:, 3])
        A = M @ M.T
        a = A / A[2, 2]
        fx = np.sqrt(max(a[0, 0] - a[0, 2] ** 2, 1e-300))
        fy = np.sqrt(max(a[1, 1] - a[1, 2] ** 2, 1e-300))
        radii.append(np.linalg.norm(c - centre) * 0.5 * min(w / fx, h / fy))
    return float(np.median(radii))


def _background_planes(xyz: np.ndarray, outer: np.ndarray, tol: float,
                       rng: np.random.Generator, tries: int = 400) -> np.ndarray:
    """Which points lie on a large plane of the background (a table, a wall): a RANSAC.

    Planes are drawn through triples of the points outside the ball ``outer`` marks; one
    counts as background when at least ``max(12, 5%)`` of those points lie within ``tol`` of
    it. Returns the mask of every point within ``tol`` of such a plane.
    """
    outside = np.flatnonzero(~outer)
    on_plane = np.zeros(len(xyz), dtype=bool)
    if len(outside) < 12:
        return on_plane
    need = max(12, int(0.05 * len(outside)))
    tri = outside[rng.integers(0, len(outside), size=(tries, 3))]
    a, b, c = xyz[tri[:, 0]], xyz[tri[:, 1]], xyz[tri[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12 * (1 + float(np.abs(a).max()))
    n = n[ok] / norm[ok, None]
    off = np.einsum("ij,ij->i", n, a[ok])
    dist = np.abs(xyz @ n.T - off)  # (points, planes)
    support = (dist[outside] < tol).sum(axis=0)
    for k in np.flatnonzero(support >= need):
        on_plane |= dist[:, k] < tol
    return on_plane


def select_object_points(
    xyz: np.ndarray,
    region: tuple[np.ndarray, float],
    frame_radius: float,
    *,
    seed: int = 0,
) -> tuple[np.ndarray, float]:
    """The points of the object, not the background: near where the highlight rays meet.

    A point is kept when it lies within ``1.5 R``, ``R = max(1.5 * ray radius, frame radius)``,
    of the rays' centre (an object photographed whole reaches little further from its centre
    than half the frame at its distance; a flash on a sphere sends every ray through the
    centre, so the rays alone say nothing of its size) and not on a large background plane
    such as a table or a wall
    (:func:`_background_planes`, tolerance ``R / 50``, planes drawn from the points beyond
    ``2 R``).

    Returns:
        The mask of object points and ``R``.
    """
    centre, ray_radius = region
    R = max(1.5 * ray_radius, frame_radius)
    dist = np.linalg.norm(xyz - centre, axis=1)
    planes = _background_planes(xyz, dist <= 2 * R, R / 50, np.random.default_rng(seed))
    return (dist <= 1.5 * R) & ~planes, R


def _ray_box(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether each ray ``o + t d``, ``t > 0``, passes through the box."""
    tmin, tmax = ray_box_span(o, d, lo, hi)
    return (tmax >= np.maximum(tmin, 0.0)) & (tmax > 0)


def auto_domain(points: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
                region: tuple[np.ndarray, float] | None, *, margin: float = 0.15
                ) -> tuple[np.ndarray, np.ndarray]:
    """A box around the object: its points, the rays' meeting region, every ray entering.

    The box holds the points and the ball of the rays' region, grows by ``margin`` times its
    longest side on every side, and then takes in, for every ray that would miss it, the
    ray's closest point to the region's centre (plus the same margin).

    Returns:
        ``(min, max)``.
    """
    parts = [np.asarray(points, float).reshape(-1, 3)]
    if region is not None:
        centre, radius = region
        parts.append(np.array([centre - radius, centre + radius]))
    allp = np.concatenate(parts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    side = float((hi - lo).max())
    if side <= 0:
        side = 1.0
    pad = margin * side
    lo, hi = lo - pad, hi + pad
    if region is not None and len(origins):
        miss = ~_ray_box(origins, dirs, lo, hi)
        if miss.any():
            t = np.maximum(np.einsum("ij,ij->i", region[0] - origins[miss], dirs[miss]), 0.0)
            near = origins[miss] + t[:, None] * dirs[miss]
            lo = np.minimum(lo, near.min(axis=0) - pad)
            hi = np.maximum(hi, near.max(axis=0) + pad)
    return lo, hi


def import_colmap(
    model_dir: str | os.PathLike,
    highlights_csv: str | os.PathLike | None,
    *,
    light: str | Mapping | Light | None,
    points: str | Collection[int] = "auto",
    max_points: int | None = None,
    domain: tuple[Sequence[float], Sequence[float]] | None = None,
    pixel_convention: str = "colmap",
) -> ColmapImport:
    """Turn a COLMAP model (text or binary) and a CSV of highlights into a scene.

    Highlights seen through a camera with lens distortion are undistorted (Newton's method on
    COLMAP's distortion model) before they become rays.

    Args:
        model_dir: The model's folder (``cameras``, ``images`` and ``points3D`` as ``.txt`` or
            ``.bin``), or a ``sparse/`` folder holding ``0/``.
        highlights_csv: The CSV of ``image,u,v`` highlights (``None``: no highlights); columns
            after the third are ignored.
        light: The light, in the model's world frame (see :func:`parse_light`); may be
            ``None`` only without highlights.
        points: Which 3D points become point constraints: ``"auto"`` (those of the object,
            near where the highlight rays meet, not the table and walls: see
            :func:`select_object_points`; all points when no two cameras have highlights),
            ``"all"``, ``"none"``, or a collection of ``POINT3D_ID``.
        max_points: Keep at most this many of them, those of least reprojection error.
        domain: The box ``(min, max)`` to reconstruct in; points outside it are dropped (with a
            warning). Without it, and with highlights, the box is sized from the rays and the
            chosen points (:func:`auto_domain`) so that every ray enters it.
        pixel_convention: ``"colmap"`` (the centre of the top-left pixel is ``(0.5, 0.5)``) or
            ``"index"`` (it is ``(0, 0)``); see the module's notes.

    Returns:
        The scene and the image and point ids behind it.

    Raises:
        SceneError: If a file is missing or malformed (``FILE:LINE: FIELD: ...``), a highlight
            names an unknown image, lies outside its image or cannot be undistorted, or an
            option is invalid.
    """
    if pixel_convention not in _PIXEL_OFFSET:
        raise SceneError(f"pixel_convention: expected 'colmap' or 'index', got "
                         f"{pixel_convention!r}")
    if max_points is not None and (isinstance(max_points, bool)
                                   or not isinstance(max_points, int | np.integer)
                                   or max_points < 0):
        raise SceneError(f"max_points: expected a non-negative integer, got {max_points!r}")
    if isinstance(points, str) and points not in ("all", "none", "auto"):
        raise SceneError(f"points: expected 'auto', 'all', 'none' or a collection of "
                         f"POINT3D_IDs, got {points!r}")
    the_light = None if light is None else parse_light(light)
    box = None if domain is None else _domain(domain)

    folder, kind = find_model(model_dir)
    ext = ".txt" if kind == "text" else ".bin"
    cameras_path = folder / f"cameras{ext}"
    images_path = folder / f"images{ext}"
    points_path = folder / f"points3D{ext}"
    cameras, images, _, _, _ = read_model(folder, points=False)

    def where(line: int) -> int | str:
        return line if kind == "text" else f"record {line}"

    if not images:
        raise SceneError(f"{images_path}: no registered images, expected at least one")
    for image in images.values():
        if image.camera_id not in cameras:
            raise _fail(images_path, where(image.line), "CAMERA_ID",
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
            raise _fail(images_path, where(image.line), "QW QX QY QZ", str(exc)) from None
        Rt = np.concatenate([R, np.asarray(image.tvec)[:, None]], axis=1)
        with np.errstate(all="ignore"):
            matrices[k] = cameras[image.camera_id].K @ Rt
        if not np.all(np.isfinite(matrices[k])):
            raise _fail(images_path, where(image.line), "TX TY TZ", "the projection matrix "
                        "K [R | t] overflows; the translation is too large")

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
        ideal, ok = camera.undistort(np.array([[pu, pv]]))
        if not ok[0]:
            coeffs = ", ".join(f"{k}={v:.3g}" for k, v in camera.distortion.items())
            raise _fail(csv_path, line, "u, v", f"({u:g}, {v:g}) cannot be undistorted: camera "
                        f"{camera.id} ({_where(cameras_path, where(camera.line))}) is "
                        f"{camera.model} ({coeffs}), whose distortion does not reach that pixel")
        spec_camera.append(index[image_id])
        spec_pixel.append((float(ideal[0, 0]), float(ideal[0, 1])))
        lines.append(line)
    if spec_camera and the_light is None:
        raise SceneError("light: missing; the highlights need a light: 'camera', "
                         "'directional:X,Y,Z' or 'point:X,Y,Z'")
    spec_camera_a = np.array(spec_camera, dtype=np.int64)
    spec_pixel_a = np.array(spec_pixel, dtype=np.float64).reshape(-1, 2)
    origins, dirs = _rays(matrices, spec_camera_a, spec_pixel_a)
    region = ray_region(origins, dirs, spec_camera_a) if len(spec_camera) else None

    # Points.
    choice: Any = points
    if isinstance(points, str) and points == "auto" and region is None:
        choice = "all"
    if isinstance(choice, str) and choice == "none":
        ids = np.zeros(0, dtype=np.int64)
        xyz = np.zeros((0, 3))
        chosen = np.zeros(0, dtype=np.int64)
    else:
        ids, xyz, errors, tracks = (read_points3d(points_path) if kind == "text"
                                    else read_points3d_bin(points_path))
        if isinstance(choice, str) and choice == "auto":
            sizes = np.array([(cameras[images[i].camera_id].width,
                               cameras[images[i].camera_id].height) for i in order])
            mask, _ = select_object_points(xyz, region,
                                           _frame_radius(region[0], matrices, sizes))
            chosen = np.flatnonzero(mask)
            if len(chosen) == 0 and len(ids):
                warnings.warn(f"{points_path}: none of its {len(ids)} points lies near where "
                              "the highlight rays meet; the scene has no point constraints "
                              "(name them with --points ID,ID,...)", SceneWarning,
                              stacklevel=2)
        else:
            chosen = _select_points(ids, choice, points_path)
        if box is not None:
            inside = np.all((xyz[chosen] >= box[0]) & (xyz[chosen] <= box[1]), axis=1)
            if not inside.all():
                warnings.warn(f"{points_path}: dropped {int((~inside).sum())} of {len(chosen)} "
                              "points outside the domain", SceneWarning, stacklevel=2)
            chosen = chosen[inside]
        if max_points is not None:
            chosen = _best(chosen, ids, errors, tracks, int(max_points))
    if box is None and region is not None:
        box = auto_domain(xyz[chosen], origins, dirs, region)
    try:
        scene = Scene(matrices, spec_camera_a, spec_pixel_a, xyz[chosen], light=the_light,
                      domain=box)
    except SceneError as exc:
        raise SceneError(_highlight_line(str(exc), lines, csv_path)) from None
    return ColmapImport(
        scene=scene,
        image_names=tuple(images[i].name for i in order),
        image_ids=tuple(order),
        point_ids=tuple(int(i) for i in ids[chosen]),
        highlight_lines=tuple(lines),
        model_dir=folder,
        model_format=kind,
    )


def _rays(matrices: np.ndarray, cams: np.ndarray, pixels: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions of pixel rays (docs/DESIGN.md section 2)."""
    if len(cams) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    M = matrices[cams, :, :3]
    with np.errstate(all="ignore"):
        centres = -np.linalg.solve(M, matrices[cams, :, 3][..., None])[..., 0]
        q = np.column_stack([pixels, np.ones(len(pixels))])
        d = np.linalg.solve(M, q[..., None])[..., 0] * np.sign(np.linalg.det(M))[:, None]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
    return centres, d


def load_colmap(
    model_dir: str | os.PathLike,
    highlights_csv: str | os.PathLike | None,
    *,
    light: str | Mapping | Light | None,
    points: str | Collection[int] = "auto",
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
