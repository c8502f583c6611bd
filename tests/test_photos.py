"""The rendered-photo bench end to end: photographs, detection, COLMAP import."""

import csv

import numpy as np
import pytest

import warpspec as ws
from warpspec.colmap import _ray_box, import_colmap, read_model
from warpspec.detect import detect_highlights, model_points, read_image
from warpspec.photos import closed_sphere, render_photos
from warpspec.synthetic import make_scene

from .test_cli import run


def _scene(name):
    return closed_sphere(views=16) if name == "closed-sphere" else make_scene(name)


@pytest.fixture(scope="module", params=["closed-sphere", "octant"])
def bench(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp(request.param)
    synthetic = _scene(request.param)
    shot = render_photos(synthetic, folder, scale=0.25, seed=1)
    return request.param, synthetic, shot


def _truth(folder):
    rows = list(csv.reader(open(folder / "highlights_true.csv")))[1:]
    truth = {}
    for name, u, v in rows:
        truth.setdefault(name, []).append((float(u), float(v)))
    return truth


def test_photos_and_model_are_what_the_scene_says(bench):
    name, synthetic, shot = bench
    assert (shot.width, shot.height) == (160, 120)
    image = read_image(shot.folder / "images" / shot.image_names[0])
    assert image.shape == (120, 160, 3) and image.dtype == np.uint8
    cameras, images, points, _, kind = read_model(shot.folder / "sparse")
    assert kind == "text"
    assert len(images) == len(synthetic.cameras) == len(shot.image_names)
    # Each true highlight is the projection of the true specular point by the model's camera.
    scene = import_colmap(shot.folder / "sparse", shot.folder / "highlights_true.csv",
                          light=synthetic.scene_dict["light"], points="none",
                          domain=synthetic.domain).scene
    origins, dirs = scene.rays()
    w = synthetic.truth_points - origins
    miss = np.linalg.norm(w - np.einsum("ij,ij->i", w, dirs)[:, None] * dirs, axis=1)
    assert miss.max() < 1e-9
    # Every spot and every object point is a tracked point seen in at least two images.
    ids, xyz, _, tracks = points
    track = dict(zip(ids.tolist(), tracks.tolist(), strict=True))
    assert all(track[i] >= 2 for i in shot.spot_point_ids)
    assert len(shot.background_point_ids) == 300
    obj = np.isin(ids, shot.object_point_ids)
    assert np.abs(synthetic.surface.signed_distance(xyz[obj])).max() < 1e-9


def test_detection_finds_the_highlights_and_the_model_rejects_the_texture(bench):
    name, synthetic, shot = bench
    truth = _truth(shot.folder)
    observed = model_points(shot.folder / "sparse" / "0")
    found = total = naive_false = false = 0
    for image_name in shot.image_names:
        image = read_image(shot.folder / "images" / image_name)
        t = np.array(truth.get(image_name, [])).reshape(-1, 2)
        plain = detect_highlights(image)
        rows = detect_highlights(image, exclude=observed[image_name])
        naive = detect_highlights(image, min_peak=0.5, min_contrast=0.2)
        for q in t:
            total += 1
            found += len(rows) > 0 and np.linalg.norm(rows[:, :2] - q, axis=1).min() < 0.5
        for det, counter in ((rows, "false"), (naive, "naive")):
            far = (np.linalg.norm(det[:, None, :2] - t[None], axis=2).min(axis=1) > 2
                   if len(t) else np.ones(len(det), bool))
            if counter == "false":
                false += int(far.sum())
            else:
                naive_false += int(far.sum())
        assert len(plain) >= len(rows)
    assert found >= 0.9 * total, (found, total)
    assert false == 0
    assert naive_false >= 10  # the spots would fool a naive threshold


def test_cli_detect_then_import_keeps_the_objects_points(bench, capsys, tmp_path):
    name, synthetic, shot = bench
    hl = tmp_path / "hl.csv"
    status, err = run(capsys, "detect", shot.folder / "images", "-o", hl, "--model",
                      shot.folder / "sparse")
    assert status == 0, err
    assert "bright spots dropped as tracked texture" in err
    out = tmp_path / "scene.json"
    light = synthetic.scene_dict["light"]
    spec = {"camera": "camera", "directional": "directional:" + ",".join(
        repr(x) for x in light.get("direction", [])), "point": "point:" + ",".join(
        repr(x) for x in light.get("position", []))}[light["type"]]
    status, err = run(capsys, "import-colmap", shot.folder / "sparse", "--highlights", hl,
                      "--light", spec, "-o", out)
    assert status == 0, err
    scene = ws.Scene.load(out)
    assert scene.num_points >= 3
    # The points are the object's (on its surface), none of the 300 on the floor and walls.
    assert np.abs(synthetic.surface.signed_distance(scene.points)).max() < 1e-6
    origins, dirs = scene.rays()
    assert _ray_box(origins, dirs, *scene.domain).all()
    assert scene.num_specularities >= 0.9 * len(synthetic.truth_points)


def test_bench_options_are_checked(tmp_path):
    synthetic = make_scene("octant")
    with pytest.raises(ws.InputError, match="^scale: 0.33 x 640x480 is not a whole number"):
        render_photos(synthetic, tmp_path, scale=0.33)
    with pytest.raises(ws.InputError, match="^saturated_spots: 5 is more than spots=2"):
        render_photos(synthetic, tmp_path, spots=2, saturated_spots=5)


def test_synth_photos_needs_a_fresh_folder(capsys, tmp_path):
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "mine.txt").write_text("keep me")
    status, err = run(capsys, "synth", "octant", "--photos", tmp_path / "busy")
    assert status == 2 and "--photos:" in err and "holds other files (mine.txt)" in err
    assert (tmp_path / "busy" / "mine.txt").read_text() == "keep me"
    status, err = run(capsys, "synth", "octant")
    assert status == 2 and "--output: required" in err
