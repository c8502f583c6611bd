"""Find specular highlights in photographs: small, near-saturated, compact, bright spots.

A highlight is much brighter than what surrounds it and small, so it survives a white top-hat
(the image minus its morphological opening by a disc larger than any highlight), and it is
near the sensor's saturation. :func:`detect_highlights` works on the luminance of the image
(8-bit, 16-bit or float, grey or colour):

1. background: the grey opening (scikit-image ``opening`` with ``disk(radius)``) of the image
   smoothed by a Gaussian of 0.7 px (sensor noise);
2. candidates: connected regions (scikit-image ``label``) where the smoothed image stands at
   least ``min_contrast`` above the background and whose brightest pixel reaches ``min_peak``
   of full scale; regions wider than the disc are not highlights (bright texture, a lamp), nor
   longer than STREAK_LENGTH discs (a cylinder's highlight under a flash is a streak);
3. centre: each candidate grows to the connected region where the image stands more than
   ``0.3 * min_contrast`` above the background, and its centre is the weighted centroid
   (label-wise sums) of the raw image minus background minus that level, so a
   clipped plateau and its shoulders both count, symmetrically; a region cut by the image's
   border is dropped (its centre is unknown);
4. texture: a candidate within ``exclude_radius`` pixels of a point given in ``exclude`` (the
   projections of the COLMAP 3D points seen in that image, see :func:`model_points`) is a
   tracked feature, not a highlight: a highlight moves with the viewpoint, so SfM does not
   track it.

Pixels follow COLMAP's convention: the centre of the top-left pixel is ``(0.5, 0.5)``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = [
    "IMAGE_SUFFIXES",
    "detect_highlights",
    "find_images",
    "model_points",
    "read_image",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def _grey(image: np.ndarray, field: str = "image") -> np.ndarray:
    """Luminance in [0, 1] of an 8-bit, 16-bit or float image, grey or colour (alpha dropped)."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (1, 2, 3, 4):
        channels = a.shape[2]
        if channels in (1, 2):
            a = a[..., 0]
        else:
            a = a[..., :3]
    elif a.ndim != 2:
        raise InputError(f"{field}: expected a 2-D grey or (H, W, 3|4) colour image, got shape "
                         f"{a.shape}")
    if a.size == 0:
        raise InputError(f"{field}: the image is empty")
    if a.dtype == np.uint8:
        g = a.astype(np.float64) / 255.0
    elif a.dtype == np.uint16:
        g = a.astype(np.float64) / 65535.0
    elif np.issubdtype(a.dtype, np.floating):
        g = a.astype(np.float64)
        if not np.all(np.isfinite(g)):
            raise InputError(f"{field}: the image has non-finite values")
    else:
        raise InputError(f"{field}: unsupported pixel type {a.dtype}; expected 8-bit, 16-bit "
                         "or float")
    if g.ndim == 3:
        g = g @ _LUMA
    return g


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG/JPEG/TIFF photograph (scikit-image's io) as it is stored.

    Raises:
        InputError: If the file is missing or not an image, naming the file.
    """
    from skimage import io as skio

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such image file")
    try:
        image = skio.imread(p)
    except Exception as exc:  # imageio raises many types for unreadable files
        raise InputError(f"{p}: cannot read it as an image ({' '.join(str(exc).split())[:120]})"
                         ) from None
    if image.ndim == 3 and image.shape[0] in (3, 4) and image.shape[2] not in (1, 2, 3, 4):
        image = np.moveaxis(image, 0, -1)
    return image


def find_images(inputs: Sequence[str | os.PathLike]) -> list[tuple[str, Path]]:
    """The photographs named by files and folders, with the name COLMAP would give each.

    A folder contributes every image under it (recursively, sorted), named by its path
    relative to that folder with ``/`` separators (as ``images.txt`` names images relative to
    the images folder); a file is named by its base name.

    Raises:
        InputError: If an input does not exist, or a folder holds no images.
    """
    found: list[tuple[str, Path]] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file()
                           and f.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise InputError(f"{p}: no images here (looked for {', '.join(IMAGE_SUFFIXES)})")
            found += [(f.relative_to(p).as_posix(), f) for f in files]
        elif p.is_file():
            found.append((p.name, p))
        else:
            raise InputError(f"{p}: no such file or folder")
    return found


def model_points(model_dir: str | os.PathLike) -> dict[str, np.ndarray]:
    """Pixels of the 3D points each image of a COLMAP model observes (text or binary).

    For every registered image: the projection (with the camera's distortion) of each 3D point
    its ``POINTS2D`` track, and the stored keypoint itself; COLMAP's pixel convention.

    Returns:
        ``(n, 2)`` pixels by image ``NAME``.
    """
    from .colmap import read_model

    cameras, images, pts, _, _ = read_model(model_dir)
    ids, xyz = pts[0], pts[1]
    position = {int(i): k for k, i in enumerate(ids)}
    out: dict[str, np.ndarray] = {}
    for image in images.values():
        obs = image.points2d if image.points2d is not None else np.zeros((0, 3))
        tracked = obs[obs[:, 2] >= 0]
        rows = [k for k in (position.get(int(i)) for i in tracked[:, 2]) if k is not None]
        pixels = [tracked[:, :2]]
        camera = cameras.get(image.camera_id)
        if rows and camera is not None:
            cam = xyz[rows] @ image.R.T + np.asarray(image.tvec)
            front = cam[:, 2] > 0
            q = cam[front] @ camera.K.T
            pixels.append(camera.distort(q[:, :2] / q[:, 2:3]))
        out[image.name] = np.concatenate(pixels).reshape(-1, 2)
    return out


STREAK_LENGTH = 10.0
"""Longest highlight, in areas of the background disc: a streak along a cylinder's axis."""


def detect_highlights(
    image: np.ndarray,
    *,
    min_peak: float = 0.8,
    min_contrast: float = 0.3,
    radius: float | None = None,
    exclude: np.ndarray | None = None,
    exclude_radius: float = 3.0,
) -> np.ndarray:
    """Find the specular highlights of one photograph.

    Args:
        image: The photograph: ``(H, W)`` grey or ``(H, W, 3|4)`` colour; 8-bit, 16-bit, or
            float with 1 as full scale.
        min_peak: Least brightness of a highlight's brightest pixel, a fraction of full scale.
        min_contrast: Least height above the local background, as a fraction of full scale.
        radius: Radius in pixels of the disc that estimates the background; a highlight must
            fit inside it. Default ``max(4, 0.02 * min(H, W))``.
        exclude: Pixels ``(n, 2)`` of tracked features (COLMAP's pixels); a candidate within
            ``exclude_radius`` of one is texture, not a highlight.
        exclude_radius: See ``exclude``, in pixels.

    Returns:
        ``(m, 5)`` rows ``u, v, peak, size, score``: the centre in COLMAP's pixel convention,
        the brightest pixel (fraction of full scale), the size in pixels of the region used for
        the centre, and the score, the height above the background at the brightest pixel.
        Sorted by decreasing score.

    Raises:
        InputError: If the image or an option is invalid (the message names it).
    """
    from scipy import ndimage
    from skimage.filters import gaussian
    from skimage.measure import label, regionprops
    from skimage.morphology import disk, opening

    grey = _grey(image)
    for name, value, low, high in (("min_peak", min_peak, 0.0, 1.0),
                                   ("min_contrast", min_contrast, 0.0, 1.0)):
        if not (isinstance(value, int | float) and math.isfinite(value)
                and low < value <= high):
            raise InputError(f"{name}: expected a number in ({low:g}, {high:g}], got {value!r}")
    if radius is None:
        radius = max(4.0, 0.02 * min(grey.shape))
    if not (isinstance(radius, int | float) and math.isfinite(radius) and radius >= 1):
        raise InputError(f"radius: expected a number of pixels >= 1, got {radius!r}")
    if not (isinstance(exclude_radius, int | float) and math.isfinite(exclude_radius)
            and exclude_radius >= 0):
        raise InputError(f"exclude_radius: expected a number of pixels >= 0, got "
                         f"{exclude_radius!r}")
    footprint = disk(int(math.ceil(radius)))
    smooth = gaussian(grey, sigma=0.7, preserve_range=True)
    background = opening(smooth, footprint)
    above = smooth - background
    strong = above >= min_contrast
    if not strong.any():
        return np.zeros((0, 5))
    seeds = label(strong, connectivity=2)
    level = 0.3 * min_contrast
    weight = grey - background - level
    grown = label(weight > 0, connectivity=2)
    max_area = float(footprint.sum())
    rim = np.concatenate([grown[0], grown[-1], grown[:, 0], grown[:, -1]])
    seen: set[int] = set(int(g) for g in np.unique(rim))  # cut by the border: no centre
    rows = []
    for region in regionprops(seeds):
        r, c = region.coords[np.argmax(grey[region.coords[:, 0], region.coords[:, 1]])]
        if grey[r, c] < min_peak:
            continue  # bright, but not near saturation: texture
        g = int(grown[r, c])
        if g == 0 or g in seen:
            continue
        seen.add(g)
        rows.append((g, r, c))
    if not rows:
        return np.zeros((0, 5))
    labels = np.array([g for g, _, _ in rows])
    mask = np.isin(grown, labels)
    w = np.where(mask, np.maximum(weight, 0.0), 0.0)
    sums = ndimage.sum(w, grown, labels)
    area = ndimage.sum(mask, grown, labels)
    rr, cc = np.indices(grown.shape)
    cy = ndimage.sum(w * rr, grown, labels) / sums
    cx = ndimage.sum(w * cc, grown, labels) / sums
    # A highlight is narrow: as wide as the disc at most, and at most STREAK_LENGTH discs
    # long (a cylinder or a bottle under a flash shows a streak along its axis, centred on the
    # specular point); bright texture, a lamp or a window is wide every way.
    widths = {p.label: p.axis_minor_length for p in regionprops(np.where(mask, grown, 0))}
    out = []
    for k, (g, r, c) in enumerate(rows):
        if area[k] > STREAK_LENGTH * max_area or widths[g] > 2.0 * radius + 1.0:
            continue  # too large for a highlight: bright texture, a lamp, a window
        out.append((cx[k] + 0.5, cy[k] + 0.5, grey[r, c], area[k], above[r, c]))
    result = np.array(out, dtype=np.float64).reshape(-1, 5)
    if exclude is not None and len(result):
        ex = np.asarray(exclude, dtype=np.float64).reshape(-1, 2)
        if len(ex):
            d = np.linalg.norm(result[:, None, :2] - ex[None], axis=2).min(axis=1)
            result = result[d > exclude_radius]
    return result[np.argsort(-result[:, 4], kind="stable")]
