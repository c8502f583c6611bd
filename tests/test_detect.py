"""Highlight detection on images whose highlights are known exactly."""

import numpy as np
import pytest

import warpspec as ws
from warpspec.detect import detect_highlights, find_images, read_image


def blob_image(centres, *, shape=(90, 120), sigma=1.2, peak=3.0, noise=0.01, seed=0,
               background=0.25):
    """A textured background with Gaussian highlights at ``centres`` (COLMAP's pixels).

    ``peak`` > 1 saturates: the blob is clipped to a plateau.
    """
    rng = np.random.default_rng(seed)
    rows, cols = np.indices(shape, dtype=np.float64)
    img = background + 0.1 * np.sin(cols / 7.0) * np.cos(rows / 5.0)
    for u, v in centres:
        # Pixel (col, row) has its centre at (col + 0.5, row + 0.5); integrate by 4x4 samples.
        acc = np.zeros(shape)
        for a in (0.125, 0.375, 0.625, 0.875):
            for b in (0.125, 0.375, 0.625, 0.875):
                acc += np.exp(-((cols + a - u) ** 2 + (rows + b - v) ** 2) / (2 * sigma**2))
        img = img + peak * acc / 16
    img = img + noise * rng.standard_normal(shape)
    return np.clip(img, 0, 1)


CENTRES = [(30.3, 20.7), (81.55, 61.15), (100.9, 30.05)]


def nearest(rows, centres):
    d = np.linalg.norm(rows[:, None, :2] - np.asarray(centres)[None], axis=2)
    return d.min(axis=0)


@pytest.mark.parametrize("kind", ["float", "uint8", "uint16", "rgb8", "rgba16"])
def test_subpixel_centres_of_saturated_blobs_in_every_pixel_type(kind):
    img = blob_image(CENTRES)
    image = {
        "float": img,
        "uint8": np.rint(img * 255).astype(np.uint8),
        "uint16": np.rint(img * 65535).astype(np.uint16),
        "rgb8": np.rint(np.stack([img] * 3, -1) * 255).astype(np.uint8),
        "rgba16": np.concatenate([np.rint(np.stack([img] * 3, -1) * 65535),
                                  np.full(img.shape + (1,), 65535)], -1).astype(np.uint16),
    }[kind]
    rows = detect_highlights(image)
    assert rows.shape == (3, 5)
    assert np.all(nearest(rows, CENTRES) < 0.1), nearest(rows, CENTRES)
    assert np.all(rows[:, 2] >= 0.99)  # saturated peaks
    assert np.all(rows[:, 3] < 60)  # compact
    assert np.all(np.diff(rows[:, 4]) <= 0)  # sorted by score


def test_noise_alone_and_dim_or_large_bright_spots_are_not_highlights():
    img = blob_image([], noise=0.03)
    assert len(detect_highlights(img)) == 0
    dim = blob_image([(60.5, 45.5)], peak=0.5)  # stands out, but far from saturation
    assert len(detect_highlights(dim)) == 0
    lamp = blob_image([])
    lamp[20:50, 30:70] = 1.0  # a large saturated area: a window or a lamp
    assert len(detect_highlights(lamp)) == 0
    cut = blob_image([(0.8, 45.2)])  # cut by the image border: no trustworthy centre
    assert len(detect_highlights(cut)) == 0


def test_tracked_points_mark_texture():
    img = blob_image(CENTRES)
    texture = np.array([[81.0, 62.0], [5.0, 5.0]])  # a tracked point 1 px from the 2nd blob
    rows = detect_highlights(img, exclude=texture, exclude_radius=3.0)
    assert len(rows) == 2
    assert np.all(nearest(rows, [CENTRES[0], CENTRES[2]]) < 0.1)
    assert len(detect_highlights(img, exclude=texture, exclude_radius=0.5)) == 3


def test_bad_images_and_options_are_named():
    with pytest.raises(ws.InputError, match="^image: expected a 2-D grey"):
        detect_highlights(np.zeros((4, 4, 4, 4)))
    with pytest.raises(ws.InputError, match="^image: unsupported pixel type int32"):
        detect_highlights(np.zeros((4, 4), dtype=np.int32))
    with pytest.raises(ws.InputError, match="^image: the image has non-finite"):
        detect_highlights(np.full((4, 4), np.nan))
    with pytest.raises(ws.InputError, match="^min_peak:"):
        detect_highlights(np.zeros((4, 4)), min_peak=1.5)
    with pytest.raises(ws.InputError, match="^radius:"):
        detect_highlights(np.zeros((4, 4)), radius=0)


def test_files_and_folders(tmp_path):
    from skimage import io as skio

    (tmp_path / "imgs" / "sub").mkdir(parents=True)
    img = np.rint(blob_image(CENTRES[:1]) * 255).astype(np.uint8)
    skio.imsave(tmp_path / "imgs" / "sub" / "a.png", img, check_contrast=False)
    skio.imsave(tmp_path / "imgs" / "b.png", img, check_contrast=False)
    (tmp_path / "imgs" / "notes.txt").write_text("not an image")
    found = find_images([tmp_path / "imgs"])
    assert [name for name, _ in found] == ["b.png", "sub/a.png"]
    rows = detect_highlights(read_image(found[1][1]))
    assert nearest(rows, CENTRES[:1])[0] < 0.1
    with pytest.raises(ws.InputError, match="no such file or folder"):
        find_images([tmp_path / "nope"])
    bad = tmp_path / "bad.png"
    bad.write_text("not a png")
    with pytest.raises(ws.InputError, match=r"bad.png: cannot read it as an image"):
        read_image(bad)


def test_a_streak_along_a_cylinder_is_one_highlight_at_its_centre():
    """A flash on a cylinder gives a streak along the axis: narrow, long, centred on the
    specular point. It is found at its centre; a bright patch wide every way is not."""
    shape = (120, 160)
    rows, cols = np.indices(shape, dtype=np.float64)
    u0, v0 = 70.3, 58.6
    img = 0.25 + 0.05 * np.sin(cols / 7.0)
    acc = np.zeros(shape)
    for a in (0.125, 0.375, 0.625, 0.875):
        for b in (0.125, 0.375, 0.625, 0.875):
            acc += np.exp(-((cols + a - u0) ** 2) / (2 * 1.2**2)
                          - ((rows + b - v0) ** 2) / (2 * 7.0**2))
    img = img + 3.0 * acc / 16
    img[20:45, 110:140] = 1.0  # a window: saturated, wide in both directions
    rows_found = detect_highlights(np.clip(img, 0, 1))
    assert len(rows_found) == 1
    assert np.hypot(rows_found[0, 0] - u0, rows_found[0, 1] - v0) < 0.1


def test_the_model_beside_the_photographs_is_found(tmp_path):
    """COLMAP's layout, DIR/images and DIR/sparse/0: detect uses that model by itself."""
    from warpspec.cli import _model_beside

    (tmp_path / "images").mkdir()
    assert _model_beside([str(tmp_path / "images")]) is None
    (tmp_path / "sparse" / "0").mkdir(parents=True)
    (tmp_path / "sparse" / "0" / "cameras.txt").write_text("# no camera\n")
    assert _model_beside([str(tmp_path / "images")]) == (tmp_path / "sparse" / "0").resolve()
    assert _model_beside([str(tmp_path / "images"), str(tmp_path / "images")]) is None
