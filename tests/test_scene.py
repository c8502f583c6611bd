"""Tests of warpspec.scene: validation, geometry and the file format."""

from __future__ import annotations

import copy
import json
import warnings

import numpy as np
import pytest

from warpspec.errors import SceneError
from warpspec.scene import (
    LIGHT_CAMERA,
    LIGHT_DIRECTIONAL,
    LIGHT_POINT,
    Light,
    Scene,
    SceneWarning,
)

K = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])


def look_at(centre, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), k=K):
    """A camera P = K [R | -R c] at `centre` looking at `target`."""
    centre = np.asarray(centre, dtype=float)
    z = np.asarray(target, dtype=float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return k @ np.hstack([R, (-R @ centre)[:, None]])


def project(P, X):
    h = P @ np.append(X, 1.0)
    return h[:2] / h[2]


def base_dict():
    """A small valid scene as its JSON object."""
    return {
        "format": "warpspec-scene",
        "version": 1,
        "cameras": [
            {"P": look_at([0.0, -5.0, 1.0]).tolist()},
            {"P": look_at([4.0, -3.0, 2.0]).tolist()},
        ],
        "light": {"type": "directional", "direction": [0.0, -1.0, 1.0]},
        "specularities": [
            {"camera": 0, "pixel": [320.0, 240.0]},
            {"camera": 1, "pixel": [300.0, 250.0]},
            {"camera": 1, "pixel": [350.0, 200.0]},
        ],
        "points": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [0.0, 1.0, -0.5]],
        "domain": {"min": [-2.0, -2.0, -2.0], "max": [2.0, 2.0, 2.0]},
    }


def write(tmp_path, data, name="scene.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


# ------------------------------------------------------------------------------ cameras, rays


def test_camera_centre_is_the_null_vector_of_P():
    centre = np.array([1.5, -4.0, 2.5])
    P = look_at(centre)
    scene = Scene([P], [], [], [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose(scene.camera_centres()[0], centre, atol=1e-12)
    np.testing.assert_allclose(P @ np.append(scene.camera_centres()[0], 1.0), 0.0, atol=1e-9)


def test_ray_of_projected_point_passes_through_the_point():
    P = look_at([3.0, -4.0, 2.0])
    X = np.array([0.3, -0.2, 0.4])
    scene = Scene([P], [0], [project(P, X)], [], light=Light("camera"))
    origins, dirs = scene.rays()
    to_x = X - origins[0]
    t = float(to_x @ dirs[0])
    assert t > 0, "the ray must point from the camera toward the point in front of it"
    np.testing.assert_allclose(origins[0] + t * dirs[0], X, atol=1e-9)
    assert abs(np.linalg.norm(dirs[0]) - 1.0) < 1e-14


def test_negated_projection_matrix_gives_same_centre_and_direction():
    P = look_at([3.0, -4.0, 2.0])
    pixel = [[250.0, 310.0]]
    a = Scene([P], [0], pixel, [], light=Light("camera"))
    b = Scene([-P], [0], pixel, [], light=Light("camera"))
    assert np.linalg.det(a.cameras[0, :, :3]) * np.linalg.det(b.cameras[0, :, :3]) < 0
    np.testing.assert_allclose(a.camera_centres(), b.camera_centres(), atol=1e-12)
    np.testing.assert_allclose(a.rays()[1], b.rays()[1], atol=1e-14)


def test_scaled_projection_matrix_gives_same_rays():
    P = look_at([3.0, -4.0, 2.0])
    a = Scene([P], [0], [[100.0, 50.0]], [], light=Light("camera"))
    b = Scene([1e-6 * P], [0], [[100.0, 50.0]], [], light=Light("camera"))
    np.testing.assert_allclose(a.rays()[0], b.rays()[0], atol=1e-9)
    np.testing.assert_allclose(a.rays()[1], b.rays()[1], atol=1e-12)


@pytest.mark.parametrize("light", [{"type": "camera"},
                                   {"type": "point", "position": [0.5, -3.0, 2.0]},
                                   {"type": "directional", "direction": [0.0, -1.0, 1.0]}])
def test_shifted_rays_and_normals_are_those_of_the_moved_pixels(light):
    data = {**base_dict(), "light": light}
    shift = (0.75, -1.5)
    moved = {**data, "specularities": [
        {**sp, "pixel": [sp["pixel"][0] + shift[0], sp["pixel"][1] + shift[1]]}
        for sp in data["specularities"]]}
    a, b = Scene.from_dict(data), Scene.from_dict(moved)
    hits = np.array([[0.1, 0.2, 0.3], [-0.4, 0.0, 0.2], [0.3, -0.2, -0.1]])
    for x, y in zip(a.rays(shift=shift), b.rays(), strict=True):
        np.testing.assert_allclose(x, y, atol=1e-14)
    np.testing.assert_allclose(a.normals(hits, shift=shift), b.normals(hits), atol=1e-14)
    assert np.abs(a.rays()[1] - b.rays()[1]).max() > 1e-4  # the shift moves the rays
    np.testing.assert_array_equal(a.spec_pixel, np.asarray(
        [sp["pixel"] for sp in data["specularities"]]))


def test_a_rays_pixel_angle_is_the_turn_of_its_pinhole_direction():
    """Each ray's pixel angle against the pinhole's own directions ``(x, y, 1)``, with
    ``x = (u - cx) / f``: the mean chord of the turn over a pixel in ``u`` and in ``v``
    (about 1/560 for these cameras), to 1e-12."""
    from warpspec.synthetic import make_scene

    synthetic = make_scene("torus", seed=0)
    scene = synthetic.scene()
    data = scene.to_dict()
    intrinsics = synthetic.truth_dict()["intrinsics"]
    f, (cx, cy) = intrinsics["focal"], intrinsics["principal"]
    uv = np.array([sp["pixel"] for sp in data["specularities"]], dtype=float)

    def direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        d = np.stack([(u - cx) / f, (v - cy) / f, np.ones_like(u)], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    at = direction(uv[:, 0], uv[:, 1])
    expected = 0.5 * (np.linalg.norm(direction(uv[:, 0] + 1, uv[:, 1]) - at, axis=1)
                      + np.linalg.norm(direction(uv[:, 0], uv[:, 1] + 1) - at, axis=1))
    np.testing.assert_allclose(scene.pixel_angles(), expected, rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(expected * f - 1.0) < 0.2)


@pytest.mark.parametrize("shift", [(np.nan, 0.0), (0.0, np.inf), (1.0,), "ab", None])
def test_a_shift_that_is_not_two_finite_numbers_is_refused(shift):
    scene = Scene.from_dict(base_dict())
    with pytest.raises(SceneError, match="shift: expected two finite"):
        scene.rays(shift=shift)
    with pytest.raises(SceneError, match="shift: expected two finite"):
        scene.normals(np.zeros((3, 3)), shift=shift)


def test_each_ray_starts_at_its_own_camera():
    scene = Scene.from_dict(base_dict())
    origins, _ = scene.rays()
    centres = scene.camera_centres()
    np.testing.assert_allclose(origins, centres[[0, 1, 1]])
    np.testing.assert_allclose(centres[1], [4.0, -3.0, 2.0], atol=1e-12)
    assert scene.num_cameras == 2 and scene.num_specularities == 3 and scene.num_points == 3


# ------------------------------------------------------------------------------ lights, normals


def test_light_direction_is_normalised_and_coded():
    light = Light("directional", [0.0, 3.0, 4.0])
    np.testing.assert_allclose(light.vector, [0.0, 0.6, 0.8])
    assert light.code == LIGHT_DIRECTIONAL
    assert Light("point", [1.0, 2.0, 3.0]).code == LIGHT_POINT
    assert Light("camera").code == LIGHT_CAMERA
    assert Light("camera").vector is None
    assert Light.from_dict(light.to_dict()) == light


def test_directional_normal_bisects_the_view_and_light_directions():
    data = base_dict()
    scene = Scene.from_dict(data)
    _, r = scene.rays()
    light = np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0)
    n = scene.normals()
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    for i in range(3):
        assert abs(n[i] @ -r[i] - n[i] @ light) < 1e-12
        # N lies in the plane of -r and L.
        assert abs(np.linalg.det(np.stack([n[i], -r[i], light]))) < 1e-12


def test_point_light_normal_depends_on_the_surface_point():
    data = base_dict()
    data["light"] = {"type": "point", "position": [0.0, -6.0, 3.0]}
    scene = Scene.from_dict(data)
    origins, r = scene.rays()
    x1 = origins + 5.0 * r
    x2 = origins + 6.0 * r
    n1, n2 = scene.normals(x1), scene.normals(x2)
    assert np.all(np.linalg.norm(n1 - n2, axis=1) > 1e-3)
    for x, n in ((x1, n1), (x2, n2)):
        to_light = np.array([0.0, -6.0, 3.0]) - x
        to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
        expected = to_light - r
        expected /= np.linalg.norm(expected, axis=1, keepdims=True)
        np.testing.assert_allclose(n, expected, atol=1e-12)


def test_point_light_normals_need_the_surface_points():
    data = base_dict()
    data["light"] = {"type": "point", "position": [0.0, -6.0, 3.0]}
    scene = Scene.from_dict(data)
    with pytest.raises(SceneError, match=r"^points: .*point light"):
        scene.normals()
    with pytest.raises(SceneError, match=r"^points: expected 3 surface points"):
        scene.normals(np.zeros((2, 3)))


def test_camera_flash_normal_is_minus_the_ray():
    data = base_dict()
    data["light"] = {"type": "camera"}
    scene = Scene.from_dict(data)
    np.testing.assert_allclose(scene.normals(), -scene.rays()[1], atol=1e-15)
    codes, vectors = scene.ray_lights()
    assert codes.dtype == np.int32 and np.all(codes == LIGHT_CAMERA)
    assert np.all(vectors == 0)


def test_camera_light_overrides_the_scene_light():
    data = base_dict()
    data["cameras"][1]["light"] = {"type": "camera"}
    scene = Scene.from_dict(data)
    codes, vectors = scene.ray_lights()
    assert codes.tolist() == [LIGHT_DIRECTIONAL, LIGHT_CAMERA, LIGHT_CAMERA]
    np.testing.assert_allclose(vectors[0], np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0))
    n = scene.normals()
    np.testing.assert_allclose(n[1:], -scene.rays()[1][1:], atol=1e-15)
    assert scene.camera_lights[0] is None and scene.camera_lights[1] == Light("camera")


def test_camera_lights_alone_are_enough():
    data = base_dict()
    del data["light"]
    for cam in data["cameras"]:
        cam["light"] = {"type": "point", "position": [0.0, 0.0, 5.0]}
    scene = Scene.from_dict(data)
    assert scene.light is None
    assert np.all(scene.ray_lights()[0] == LIGHT_POINT)


# ------------------------------------------------------------------------------ file format


def test_save_load_round_trip(tmp_path):
    data = base_dict()
    data["cameras"][0]["light"] = {"type": "point", "position": [0.1, 0.2, 0.3]}
    scene = Scene.from_dict(data)
    path = tmp_path / "out.json"
    scene.save(path)
    again = Scene.load(path)
    for name in ("cameras", "spec_camera", "spec_pixel", "points"):
        np.testing.assert_array_equal(getattr(again, name), getattr(scene, name))
    np.testing.assert_array_equal(again.domain[0], scene.domain[0])
    np.testing.assert_array_equal(again.domain[1], scene.domain[1])
    assert again.light == scene.light
    assert again.camera_lights == scene.camera_lights
    assert again.to_dict() == scene.to_dict()
    assert Scene.from_dict(scene.to_dict()).to_dict() == scene.to_dict()


def test_load_a_valid_file(tmp_path):
    text = """{
      "format": "warpspec-scene", "version": 1,
      "cameras": [{"P": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5]]}],
      "light": {"type": "camera"},
      "specularities": [{"camera": 0, "pixel": [0.1, -0.2]}],
      "points": [[0, 0, 0], [0.5, 0.5, 0]]
    }"""
    scene = Scene.load(write(tmp_path, text))
    np.testing.assert_allclose(scene.camera_centres(), [[0.0, 0.0, -5.0]])
    assert scene.domain is None
    lo, hi = scene.bounds(margin=0.2)
    np.testing.assert_allclose(lo, [-0.1, -0.1, -0.1])
    np.testing.assert_allclose(hi, [0.6, 0.6, 0.1])
    assert scene.spec_camera.dtype == np.int64 and scene.cameras.dtype == np.float64


def test_from_dict_does_not_modify_its_input():
    data = base_dict()
    data["cameras"][0]["P"] = np.asarray(data["cameras"][0]["P"])
    data["points"] = np.asarray(data["points"])
    before = copy.deepcopy(data)
    scene = Scene.from_dict(data)
    assert data.keys() == before.keys()
    np.testing.assert_array_equal(data["points"], before["points"])
    np.testing.assert_array_equal(data["cameras"][0]["P"], before["cameras"][0]["P"])
    assert data["light"] == before["light"] and data["specularities"] == before["specularities"]
    assert not np.shares_memory(scene.points, data["points"])


def test_constructor_copies_and_never_changes_its_input_arrays():
    P = look_at([0.0, -5.0, 1.0])[None]
    cams, spec_cam = P.copy(), np.array([0])
    pix, pts = np.array([[320.0, 240.0]]), np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    direction = np.array([0.0, -2.0, 2.0])
    inputs = [cams, spec_cam, pix, pts, direction]
    before = [a.copy() for a in inputs]
    light = Light("directional", direction)
    scene = Scene(cams, spec_cam, pix, pts, light=light, domain=(-np.ones(3), np.ones(3)))
    for a, b in zip(inputs, before, strict=True):
        np.testing.assert_array_equal(a, b)
    cams[0, 0, 0] = 99.0
    pts[0] = 99.0
    assert scene.cameras[0, 0, 0] != 99.0 and scene.points[0, 0] == 0.0
    with pytest.raises(ValueError):
        scene.points[0, 0] = 1.0  # read-only: a validated scene cannot change


def test_unknown_keys_are_ignored_with_a_warning():
    data = base_dict()
    data["comment"] = "hello"
    data["cameras"][0]["name"] = "left"
    data["_private"] = 1
    with pytest.warns(SceneWarning, match=r"comment, cameras\[0\]\.name$"):
        Scene.from_dict(data)


# ------------------------------------------------------------------------------ rejections


def rejects(data, match):
    with pytest.raises(SceneError, match=match):
        Scene.from_dict(data)


def test_missing_file_is_rejected(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.json'?: no such scene file"):
        Scene.load(tmp_path / "nope.json")


def test_unreadable_file_is_rejected(tmp_path):
    with pytest.raises(SceneError, match="is a directory"):
        Scene.load(tmp_path)
    path = tmp_path / "binary.json"
    path.write_bytes(b"{\xff\xfe\x00}")
    with pytest.raises(SceneError, match="binary.json'?: not valid JSON"):
        Scene.load(path)
    with pytest.raises(SceneError, match=r"^path: expected a file path, got 3"):
        Scene.load(3)


def test_not_json_says_line_and_column(tmp_path):
    path = write(tmp_path, '{\n  "format": "warpspec-scene",\n  "version": 1,,\n}')
    with pytest.raises(SceneError, match=r"not valid JSON: .* line 3 column 16"):
        Scene.load(path)


def test_duplicate_keys_are_rejected(tmp_path):
    with pytest.raises(SceneError, match="duplicate key 'points'"):
        Scene.load(write(tmp_path, '{"points": [], "points": []}'))


def test_huge_integer_literal_is_rejected(tmp_path):
    with pytest.raises(SceneError, match="not valid JSON"):
        Scene.load(write(tmp_path, '{"version": ' + "9" * 5000 + "}"))


def test_deeply_nested_json_is_rejected(tmp_path):
    with pytest.raises(SceneError, match="nested too deeply"):
        Scene.load(write(tmp_path, "[" * 100000 + "]" * 100000))


def test_top_level_must_be_an_object(tmp_path):
    with pytest.raises(SceneError, match=r"^scene: expected a JSON object at the top level, got"):
        Scene.load(write(tmp_path, "[1, 2, 3]"))


def test_wrong_format_is_rejected():
    data = base_dict()
    data["format"] = "ply"
    rejects(data, r"^format: expected \"warpspec-scene\", got 'ply'")
    del data["format"]
    rejects(data, r"^format: missing")


def test_wrong_version_is_rejected():
    data = base_dict()
    for bad in (2, "1", 1.0, True):
        data["version"] = bad
        rejects(data, r"^version: unsupported version .*expected 1")
    del data["version"]
    rejects(data, r"^version: missing")


def test_no_cameras_is_rejected():
    data = base_dict()
    data["cameras"] = []
    rejects(data, r"^cameras: the scene has no cameras")
    del data["cameras"]
    rejects(data, r"^cameras: missing")
    data["cameras"] = {"P": np.eye(3, 4).tolist()}
    rejects(data, r"^cameras: expected a list of cameras")


def test_camera_without_P_is_rejected():
    data = base_dict()
    data["cameras"][1] = {"light": {"type": "camera"}}
    rejects(data, r"^cameras\[1\]\.P: missing")
    data["cameras"][1] = [[1, 0, 0, 0]]
    rejects(data, r"^cameras\[1\]: expected an object")


def test_projection_matrix_of_wrong_shape_is_rejected():
    data = base_dict()
    data["cameras"][1]["P"] = np.eye(3).tolist()
    rejects(data, r"^cameras\[1\]\.P: expected a 3x4 matrix of finite numbers, got shape \(3, 3\)")
    data["cameras"][1]["P"] = [[1, 0, 0, 0], [0, 1, 0], [0, 0, 1, 0]]
    rejects(data, r"^cameras\[1\]\.P: expected a 3x4 matrix .*rows of lengths \[3, 4\]")
    data["cameras"][1]["P"] = [[1, 0, 0, "0"], [0, 1, 0, 0], [0, 0, 1, 0]]
    rejects(data, r"^cameras\[1\]\.P: expected a 3x4 matrix of finite numbers, got \[\[1, 0")
    data["cameras"][1]["P"] = "identity"
    rejects(data, r"^cameras\[1\]\.P: expected a 3x4 matrix of finite numbers, got 'identity'")


def test_singular_projection_matrix_is_rejected():
    data = base_dict()
    data["cameras"][0]["P"] = [[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 1]]
    rejects(data, r"^cameras\[0\]\.P: .*singular left 3x3 block")
    data["cameras"][0]["P"] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1e-14, 1]]
    rejects(data, r"^cameras\[0\]\.P: .*singular left 3x3 block")


def test_non_finite_projection_matrix_is_rejected(tmp_path):
    text = json.dumps(base_dict()).replace("800.0", "NaN", 1)
    with pytest.raises(SceneError, match=r"^cameras\[0\]\.P: expected .* got nan at row 0"):
        Scene.load(write(tmp_path, text))


def test_non_finite_numbers_are_rejected(tmp_path):
    data = base_dict()
    data["points"][1] = [0.0, float("inf"), 0.0]
    rejects(data, r"^points\[1\]: expected 3 finite numbers \[x, y, z\], got \[0, inf, 0\]")
    data = base_dict()
    data["specularities"][2]["pixel"] = [float("nan"), 0.0]
    rejects(data, r"^specularities\[2\]\.pixel: expected two finite numbers")
    text = json.dumps(base_dict()).replace("[1.0, 0.0, 0.5]", "[1.0, -Infinity, 0.5]")
    with pytest.raises(SceneError, match=r"^points\[1\]: expected 3 finite numbers"):
        Scene.load(write(tmp_path, text))
    text = json.dumps(base_dict()).replace("[1.0, 0.0, 0.5]", "[1.0, 1e400, 0.5]")
    with pytest.raises(SceneError, match=r"^points\[1\]: expected 3 finite numbers"):
        Scene.load(write(tmp_path, text))


def test_pixel_that_is_not_two_numbers_is_rejected():
    data = base_dict()
    for bad in ([1.0], [1.0, 2.0, 3.0], "12", [1.0, "2"], [1.0, True], None, {"u": 1, "v": 2}):
        data["specularities"][1]["pixel"] = bad
        rejects(data, r"^specularities\[1\]\.pixel: expected two finite numbers \[u, v\]")
    del data["specularities"][1]["pixel"]
    rejects(data, r"^specularities\[1\]\.pixel: missing")


def test_camera_index_out_of_range_is_rejected():
    data = base_dict()
    data["specularities"][2]["camera"] = 7
    rejects(data, r"^specularities\[2\]\.camera: index 7 out of range, the scene has 2 cameras")
    data["specularities"][2]["camera"] = -1
    rejects(data, r"^specularities\[2\]\.camera: index -1 out of range")
    data["specularities"][2]["camera"] = 10**40
    rejects(data, r"^specularities\[2\]\.camera: index 1000.* out of range")


def test_camera_index_that_is_not_an_integer_is_rejected():
    data = base_dict()
    for bad in (1.0, "1", True, False, None, [0]):
        data["specularities"][0]["camera"] = bad
        rejects(data, r"^specularities\[0\]\.camera: expected an integer camera index")
    del data["specularities"][0]["camera"]
    rejects(data, r"^specularities\[0\]\.camera: missing")


def test_zero_or_non_finite_light_direction_is_rejected():
    data = base_dict()
    data["light"]["direction"] = [0, 0, 0]
    rejects(data, r"^light\.direction: expected a non-zero vector")
    data["light"]["direction"] = [0, float("nan"), 1]
    rejects(data, r"^light\.direction: expected 3 finite numbers")
    data["light"]["direction"] = [0, 1]
    rejects(data, r"^light\.direction: expected 3 finite numbers")
    del data["light"]["direction"]
    rejects(data, r"^light\.direction: missing")
    with pytest.raises(SceneError, match=r"^light\.direction: expected a non-zero vector"):
        Light("directional", np.zeros(3))


def test_unknown_light_type_is_rejected():
    data = base_dict()
    data["light"] = {"type": "spot", "position": [0, 0, 1]}
    rejects(data, r"^light\.type: unknown light type 'spot', expected \"directional\"")
    data["light"] = {"direction": [0, 0, 1]}
    rejects(data, r"^light\.type: missing")
    data["light"] = "sun"
    rejects(data, r"^light: expected an object like")
    data = base_dict()
    data["cameras"][1]["light"] = {"type": 3}
    rejects(data, r"^cameras\[1\]\.light\.type: unknown light type 3")
    with pytest.raises(SceneError, match=r"^light\.type: unknown light type 'laser'"):
        Light("laser")


def test_non_finite_point_light_position_is_rejected():
    data = base_dict()
    data["light"] = {"type": "point", "position": [0, float("inf"), 1]}
    rejects(data, r"^light\.position: expected 3 finite numbers")
    data["light"] = {"type": "point"}
    rejects(data, r"^light\.position: missing")
    data = base_dict()
    data["cameras"][0]["light"] = {"type": "point", "position": [0, 0, float("nan")]}
    rejects(data, r"^cameras\[0\]\.light\.position: expected 3 finite numbers")


def test_inverted_or_empty_domain_is_rejected():
    data = base_dict()
    data["domain"] = {"min": [0, 0, 0], "max": [1, -1, 1]}
    rejects(
        data, r"^domain: max must exceed min on every axis, got min=\[0, 0, 0\] max=\[1, -1, 1\]"
    )
    data["domain"] = {"min": [0, 0, 0], "max": [1, 1, 0]}
    rejects(data, r"^domain: max must exceed min on every axis")
    data["domain"] = {"min": [0, 0, 0]}
    rejects(data, r"^domain\.max: missing")
    data["domain"] = {"min": [0, 0], "max": [1, 1, 1]}
    rejects(data, r"^domain\.min: expected 3 finite numbers")
    data["domain"] = [[0, 0, 0], [1, 1, 1]]
    rejects(data, r"^domain: expected an object")


def test_points_that_are_not_3_vectors_are_rejected():
    data = base_dict()
    data["points"] = [[0, 0, 0], [1, 2]]
    rejects(data, r"^points\[1\]: expected 3 finite numbers \[x, y, z\], got \[1, 2\]")
    data["points"] = [[0, 0, 0], "1 2 3"]
    rejects(data, r"^points\[1\]: expected 3 finite numbers")
    data["points"] = {"0": [0, 0, 0]}
    rejects(data, r"^points: expected a list of \[x, y, z\] points")
    data["points"] = [0, 0, 0]
    rejects(data, r"^points\[0\]: expected 3 finite numbers \[x, y, z\], got 0")


def test_specularities_that_are_not_a_list_of_objects_are_rejected():
    data = base_dict()
    data["specularities"] = {"camera": 0, "pixel": [1, 2]}
    rejects(data, r"^specularities: expected a list of")
    data["specularities"] = [[0, [1, 2]]]
    rejects(data, r"^specularities\[0\]: expected an object")


def test_no_constraints_at_all_is_rejected():
    data = base_dict()
    data["specularities"] = []
    data["points"] = []
    rejects(data, r"^scene: no constraints")
    del data["specularities"], data["points"]
    rejects(data, r"^scene: no constraints")


def test_specularity_without_a_light_is_rejected():
    data = base_dict()
    del data["light"]
    rejects(data, r"^light: missing: specularities\[0\] is seen in camera 0")
    data["cameras"][0]["light"] = {"type": "camera"}
    rejects(data, r"^light: missing: specularities\[1\] is seen in camera 1, .*cameras\[1\]\.light")
    data["specularities"] = []
    assert Scene.from_dict(data).light is None  # points only: no light needed


def test_light_straight_behind_the_surface_is_rejected():
    P = look_at([0.0, -5.0, 0.0])
    scene = Scene([P], [0], [[320.0, 240.0]], [], light=Light("camera"))
    r = scene.rays()[1][0]
    with pytest.raises(SceneError, match=r"^specularities\[0\]: the light direction equals"):
        Scene([P], [0], [[320.0, 240.0]], [], light=Light("directional", r))


def test_constructor_rejects_inconsistent_arrays():
    P = look_at([0.0, -5.0, 1.0])
    light = Light("camera")
    with pytest.raises(SceneError, match=r"^cameras: expected a list of 3x4 matrices"):
        Scene([np.eye(3)], [], [], [[0, 0, 0]])
    with pytest.raises(SceneError, match=r"^cameras: expected .*got 'P'"):
        Scene("P", [], [], [[0, 0, 0]])
    with pytest.raises(SceneError, match=r"^cameras: the scene has no cameras"):
        Scene(np.zeros((0, 3, 4)), [], [], [[0, 0, 0]])
    with pytest.raises(SceneError, match=r"^specularities: 2 camera indices but 1 pixels"):
        Scene([P], [0, 0], [[1.0, 2.0]], [], light=light)
    with pytest.raises(SceneError, match=r"^specularities\[0\]\.camera: expected an integer"):
        Scene([P], [0.0], [[1.0, 2.0]], [], light=light)
    with pytest.raises(SceneError, match=r"^specularities: expected a 1-D array of integer"):
        Scene([P], np.array([0.0]), [[1.0, 2.0]], [], light=light)
    with pytest.raises(SceneError, match=r"^specularities\[0\]\.camera: index 1 out of range"):
        Scene([P], np.array([1]), [[1.0, 2.0]], [], light=light)
    with pytest.raises(SceneError, match=r"^camera_lights: expected 1 entries"):
        Scene([P], [0], [[1.0, 2.0]], [], camera_lights=[light, light])
    with pytest.raises(SceneError, match=r"^cameras\[0\]\.light: expected a Light or None"):
        Scene([P], [0], [[1.0, 2.0]], [], camera_lights=["flash"])
    with pytest.raises(SceneError, match=r"^points\[1\]: expected finite numbers"):
        Scene([P], [], [], [[0, 0, 0], [0, np.nan, 0]])
    with pytest.raises(SceneError, match=r"^points: expected a list of \[x, y, z\] points"):
        Scene([P], [], [], [["a", "b", "c"]])
    with pytest.raises(SceneError, match=r"^cameras\[0\]\.P: the camera centre .* not finite"):
        Scene([np.hstack([np.eye(3) * 1e-200, np.full((3, 1), 1e200)])], [], [], [[0, 0, 0]])


# ------------------------------------------------------------------------------ bounds


def test_bounds_are_the_domain_when_given():
    lo, hi = Scene.from_dict(base_dict()).bounds(margin=5.0)
    np.testing.assert_array_equal(lo, [-2.0, -2.0, -2.0])
    np.testing.assert_array_equal(hi, [2.0, 2.0, 2.0])


def test_bounds_grow_the_bounding_box_of_the_points():
    data = base_dict()
    del data["domain"]
    lo, hi = Scene.from_dict(data).bounds(margin=0.5)
    np.testing.assert_allclose(lo, [-0.5, -0.5, -1.0])
    np.testing.assert_allclose(hi, [1.5, 1.5, 1.0])


def test_bounds_need_two_distinct_points_or_a_domain():
    data = base_dict()
    del data["domain"]
    data["points"] = [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]
    with pytest.raises(SceneError, match=r'^domain: cannot be derived from 1 distinct.*"domain"'):
        Scene.from_dict(data).bounds()
    data["points"] = []
    with pytest.raises(SceneError, match=r"^domain: cannot be derived from 0 distinct"):
        Scene.from_dict(data).bounds()


def test_bounds_with_zero_margin_of_flat_points_are_rejected():
    data = base_dict()
    del data["domain"]
    data["points"] = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]
    scene = Scene.from_dict(data)
    with pytest.raises(SceneError, match=r"^domain: the box derived from the points is flat"):
        scene.bounds(margin=0.0)
    assert np.all(np.subtract(*scene.bounds()[::-1]) > 0)
    for bad in (-0.1, float("nan"), True, "0.2"):
        with pytest.raises(SceneError, match=r"^margin: expected a finite number >= 0"):
            scene.bounds(margin=bad)


# ------------------------------------------------------------------------------ check()


def test_check_of_a_clean_scene_is_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Scene.from_dict(base_dict()).check() == []


def test_check_warns_about_a_ray_that_never_enters_the_domain():
    data = base_dict()
    data["specularities"][1]["pixel"] = [5000.0, 240.0]
    with pytest.warns(SceneWarning, match=r"^specularities\[1\]: .* never enters the domain box"):
        messages = Scene.from_dict(data).check()
    assert len(messages) == 1


def test_check_warns_about_a_ray_pointing_away_from_the_domain():
    data = base_dict()
    scene = Scene.from_dict(data)
    # A box behind camera 0 (at y = -5, looking toward +y).
    with pytest.warns(SceneWarning) as record:
        messages = scene.check(bounds=([-1.0, -9.0, -1.0], [1.0, -8.0, 3.0]))
    assert messages[0].startswith("specularities[0]: ")
    assert "points away from the domain box" in messages[0]
    assert [str(w.message) for w in record] == messages


def test_check_warns_about_a_point_outside_the_domain():
    data = base_dict()
    data["points"].append([0.0, 0.0, 3.0])
    with pytest.warns(SceneWarning, match=r"^points\[3\]: \[0, 0, 3\] lies outside the domain"):
        Scene.from_dict(data).check()


def test_check_warns_about_a_normal_facing_away_from_its_camera():
    data = base_dict()
    data["light"]["direction"] = [0.0, 1.0, -0.05]  # sign flipped: the light is behind
    with pytest.warns(SceneWarning, match=r"^specularities\[0\]: the normal makes 8\d\.\d degrees"):
        messages = Scene.from_dict(data).check()
    assert "specularities[0]" in messages[0]


def test_check_warns_about_collinear_points():
    data = base_dict()
    data["points"] = [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]]
    with pytest.warns(SceneWarning, match=r"^points: all 3 points are collinear"):
        Scene.from_dict(data).check()


def test_check_reports_an_underivable_domain_instead_of_raising():
    data = base_dict()
    del data["domain"]
    data["points"] = [[0.0, 0.0, 0.0]]
    with pytest.warns(SceneWarning, match=r"^domain: cannot be derived"):
        assert len(Scene.from_dict(data).check()) == 1
    with pytest.raises(SceneError, match=r"^bounds: max must exceed min"):
        Scene.from_dict(data).check(bounds=([0, 0, 0], [0, 1, 1]))


@pytest.mark.parametrize(("offset", "collinear"), [(1e-7, True), (1e-5, False)])
def test_check_and_the_start_share_the_collinear_tolerance(offset, collinear):
    # Three points on the x axis, the middle one lifted by ``offset`` along z: the second
    # singular value over the first is about 0.47 * offset, on either side of COLLINEAR_TOL.
    from warpspec.geometry import COLLINEAR_TOL
    from warpspec.grid import Grid
    from warpspec.solver import initial_plane

    assert (0.47 * offset <= COLLINEAR_TOL) == collinear
    data = base_dict()
    data["points"] = [[-1.0, 0.0, 0.0], [0.0, 0.0, offset], [1.0, 0.0, 0.0]]
    scene = Scene.from_dict(data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        messages = scene.check()
    assert any("collinear" in m for m in messages) == collinear
    assert len(caught) == len(messages)
    grid = Grid(origin=np.full(3, -1.0), spacing=0.05, shape=(41, 41, 41))
    _, normal = initial_plane(scene, grid)
    # A plane through the points has the normal +-y; the fallback takes the constraint normals.
    fitted = abs(abs(float(normal[1])) - 1.0) < 1e-9
    assert fitted == (not collinear)


# ------------------------------------------------------------------------------ frames


@pytest.mark.parametrize("kind", ["directional", "point", "camera", "per-camera"])
def test_a_translated_scene_is_the_same_scene_measured_from_elsewhere(kind):
    data = base_dict()
    if kind == "per-camera":
        data["cameras"][1]["light"] = {"type": "point", "position": [1.0, -2.0, 3.0]}
    elif kind != "directional":
        data["light"] = ({"type": "camera"} if kind == "camera"
                         else {"type": "point", "position": [0.5, -4.0, 3.0]})
    scene = Scene.from_dict(data)
    origin = np.array([1.0e6, -2.5e5, 37.0])
    far = scene.translated(-origin)  # every world position moved by +origin
    o0, d0 = scene.rays()
    o1, d1 = far.rays()
    np.testing.assert_allclose(o1 - origin, o0, atol=1e-9)
    np.testing.assert_allclose(d1, d0, atol=1e-12)
    np.testing.assert_array_equal(far.spec_pixel, scene.spec_pixel)
    np.testing.assert_allclose(far.points, scene.points + origin, rtol=0, atol=0)
    np.testing.assert_allclose(far.domain[0], scene.domain[0] + origin)
    hits = o0 + 3.0 * d0  # the normals the law demands move with the surface points
    np.testing.assert_allclose(far.normals(hits + origin), scene.normals(hits), atol=1e-9)
    back = far.translated(origin)
    np.testing.assert_allclose(back.cameras, scene.cameras, rtol=1e-9, atol=1e-6)
    assert back.light == scene.light or back.light.kind == "point"


@pytest.mark.parametrize("origin", [[1.0, 2.0], [0.0, float("nan"), 0.0], "far"])
def test_a_translation_that_is_not_a_point_is_refused(origin):
    with pytest.raises(SceneError, match="origin"):
        Scene.from_dict(base_dict()).translated(origin)
