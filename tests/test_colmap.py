"""Import of COLMAP text models: cameras, points and highlights rebuilt exactly, bad lines named."""

import math
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import warpspec as ws
from warpspec.colmap import (
    ColmapCamera,
    import_colmap,
    load_colmap,
    parse_light,
    rotation_from_quaternion,
)

WIDTH, HEIGHT = 640, 480

# Known world points: the specular points each highlight sees, and the SfM points.
SPECULAR = np.array([[0.3, -0.2, 0.1], [-0.25, 0.15, 0.05], [0.05, 0.3, -0.1], [0.2, 0.1, 0.25]])
POINTS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.4, 0.4, 0.4],
                   [5.0, 5.0, 5.0]])
ERRORS = [0.5, 0.2, 0.9, 0.1, 2.0]


def look_at(centre, target=(0.0, 0.0, 0.0)):
    """World-to-camera rotation of a camera at ``centre`` looking at ``target``."""
    forward = np.asarray(target, float) - centre
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def intrinsics(model):
    """PARAMS of each model, with the pinhole part fx=800, fy=790 (f=800), cx=320.5, cy=240.25."""
    return {
        "SIMPLE_PINHOLE": [800.0, 320.5, 240.25],
        "PINHOLE": [800.0, 790.0, 320.5, 240.25],
        "SIMPLE_RADIAL": [800.0, 320.5, 240.25, 0.0],
        "RADIAL": [800.0, 320.5, 240.25, 0.0, 0.0],
        "OPENCV": [800.0, 790.0, 320.5, 240.25, -0.1, 0.01, 0.001, -0.002],
    }[model]


def K_of(model):
    p = intrinsics(model)
    fx, fy, cx, cy = (p[0], p[1], p[2], p[3]) if model in ("PINHOLE", "OPENCV") else \
        (p[0], p[0], p[1], p[2])
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])


def write_model(folder: Path, *, model="PINHOLE", names=None, header=True, convention="colmap"):
    """A COLMAP text model of 4 cameras around the origin; returns the camera centres and R, t."""
    folder.mkdir(parents=True, exist_ok=True)
    centres = np.array([[4.0, 0.5, 1.0], [0.3, 4.0, 1.5], [-3.5, -1.0, 2.0], [0.5, -3.8, 2.5]])
    names = names or [f"img{i:03d}.png" for i in range(len(centres))]
    rotations = [look_at(c) for c in centres]
    K = K_of(model)
    (folder / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n"
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        f"# Number of cameras: 2\n"
        f"1 {model} {WIDTH} {HEIGHT} {' '.join(repr(p) for p in intrinsics(model))}\n"
        f"2 {model} {WIDTH} {HEIGHT} {' '.join(repr(p) for p in intrinsics(model))}\n"
    )
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    # IMAGE_IDs out of order on purpose: the scene's cameras follow increasing IMAGE_ID.
    ids = [7, 3, 12, 5]
    for image_id, c, R, name in zip(ids, centres, rotations, names, strict=True):
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        t = -R @ c
        values = " ".join(repr(float(v)) for v in (w, x, y, z, *t))
        lines.append(f"{image_id} {values} {1 + image_id % 2} {name}")
        lines.append("100.5 200.25 1 300.0 12.5 -1" if image_id == 3 else "")
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    rows = ["# 3D point list with one line of data per point:",
            "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"]
    for k, (p, e) in enumerate(zip(POINTS, ERRORS, strict=True)):
        rows.append(f"{10 + k} {' '.join(repr(float(v)) for v in p)} 200 100 50 {e} "
                    f"{' '.join(f'{i} {k}' for i in ids[: 2 + k % 3])}")
    (folder / "points3D.txt").write_text("\n".join(rows) + "\n")

    # One highlight per image, each the projection of a known specular point.
    csv_lines = ["image,u,v"] if header else []
    offset = 0.5 if convention == "index" else 0.0
    for k, (c, R, name) in enumerate(zip(centres, rotations, names, strict=True)):
        q = K @ (R @ SPECULAR[k] - R @ c)
        u, v = q[:2] / q[2]
        csv_lines.append(f"{name},{float(u - offset)!r},{float(v - offset)!r}")
    (folder / "highlights.csv").write_text("\n".join(csv_lines) + "\n")
    order = np.argsort(ids)
    return centres[order], [rotations[i] for i in order], order


def distance_to_rays(scene, targets):
    origins, dirs = scene.rays()
    w = targets - origins
    t = np.einsum("ij,ij->i", w, dirs)
    return np.linalg.norm(w - t[:, None] * dirs, axis=1), t


@pytest.fixture
def model(tmp_path):
    folder = tmp_path / "sparse"
    write_model(folder)
    return folder


@pytest.mark.parametrize("camera_model", ["SIMPLE_PINHOLE", "PINHOLE"])
def test_rays_of_the_imported_scene_pass_through_the_specular_points(tmp_path, camera_model):
    folder = tmp_path / camera_model
    centres, _, order = write_model(folder, model=camera_model)
    # points="all": the default keeps only the points near where the rays meet.
    scene = load_colmap(folder, folder / "highlights.csv", light="camera", points="all")
    assert scene.num_cameras == 4
    np.testing.assert_allclose(scene.camera_centres(), centres, atol=1e-9)
    # Highlight k was written for the k-th image in file order; the camera is its rank by id.
    spec_targets = SPECULAR[: scene.num_specularities]
    dist, depth = distance_to_rays(scene, spec_targets)
    assert np.all(dist < 1e-6), dist
    assert np.all(depth > 0)  # the specular points lie in front of their cameras
    np.testing.assert_array_equal(scene.spec_camera, np.argsort(order))
    np.testing.assert_array_equal(scene.points, POINTS)


def test_projection_matrices_are_K_R_t_from_colmaps_quaternion(model):
    imported = import_colmap(model, model / "highlights.csv", light="camera")
    scene = imported.scene
    assert imported.image_ids == (3, 5, 7, 12)
    assert imported.image_names == ("img001.png", "img003.png", "img000.png", "img002.png")
    for cam, (P, name) in enumerate(zip(scene.cameras, imported.image_names, strict=True)):
        # The specular point of each image projects onto the highlight written for it.
        q = P @ np.append(SPECULAR[int(name[3:6])], 1.0)
        assert q[2] > 0
        np.testing.assert_allclose(q[:2] / q[2], scene.spec_pixel[scene.spec_camera == cam][0],
                                   atol=1e-9)
    # The quaternion convention: qw qx qy qz, Hamilton, world to camera.
    theta = 0.3
    R = rotation_from_quaternion([math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)])
    expected = np.array([[math.cos(theta), -math.sin(theta), 0], [math.sin(theta),
                         math.cos(theta), 0], [0, 0, 1]])
    np.testing.assert_allclose(R, expected, atol=1e-15)
    q = Rotation.from_euler("xyz", [0.4, -1.1, 2.0]).as_quat()  # x y z w
    np.testing.assert_allclose(rotation_from_quaternion([q[3], *q[:3]]),
                               Rotation.from_quat(q).as_matrix(), atol=1e-14)


def test_index_pixel_convention_adds_half_a_pixel(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    write_model(a)
    write_model(b, convention="index", header=False)
    colmap = load_colmap(a, a / "highlights.csv", light="camera")
    index = load_colmap(b, b / "highlights.csv", light="camera", pixel_convention="index")
    np.testing.assert_allclose(index.spec_pixel, colmap.spec_pixel, atol=1e-9)
    dist, _ = distance_to_rays(index, SPECULAR)
    assert np.all(dist < 1e-6)


def test_highlights_may_name_images_by_base_name(tmp_path):
    folder = tmp_path / "m"
    names = [f"cam{i}/frame.{i}.jpg" for i in range(4)]
    write_model(folder, names=names)
    csv = folder / "highlights.csv"
    csv.write_text(csv.read_text().replace("cam0/", "").replace("cam2/", ""))
    scene = load_colmap(folder, csv, light="camera")
    assert np.all(distance_to_rays(scene, SPECULAR)[0] < 1e-6)


def test_point_selection(model):
    csv = model / "highlights.csv"
    assert load_colmap(model, csv, light="camera", points="none").num_points == 0
    # points="all" where the test is about the other options, not the automatic choice.
    best = load_colmap(model, csv, light="camera", points="all", max_points=2)
    np.testing.assert_array_equal(best.points, POINTS[[1, 3]])  # errors 0.2 and 0.1
    chosen = import_colmap(model, csv, light="camera", points=[14, 10])
    assert chosen.point_ids == (10, 14)
    with pytest.warns(ws.SceneWarning, match="dropped 1 of 5 points outside the domain"):
        boxed = load_colmap(model, csv, light="camera", points="all",
                            domain=([-2, -2, -2], [2, 2, 2]))
    assert boxed.num_points == 4
    assert boxed.domain is not None


def test_lights_from_specs():
    assert parse_light("camera") == ws.Light("camera")
    assert parse_light("directional:0,0,2") == ws.Light("directional", [0, 0, 1])
    assert parse_light("point: 1 2 3") == ws.Light("point", [1, 2, 3])
    assert parse_light('{"type": "point", "position": [1, 2, 3]}') == ws.Light("point",
                                                                               [1, 2, 3])
    for bad, field in [("sideways", "--light"), ("directional:1,2", "--light"),
                       ("directional:0,0,0", "--light.direction"), ("{nope", "--light"),
                       ('{"type": "laser"}', "--light.type")]:
        with pytest.raises(ws.SceneError, match=f"^{field}:"):
            parse_light(bad, field="--light")


def test_distorted_highlights_are_undistorted_onto_the_specular_points(tmp_path):
    # Lens distortion used to be ignored with a warning; the highlights are now undistorted.
    folder = tmp_path / "opencv"
    write_model(folder, model="OPENCV")
    camera = ColmapCamera(1, "OPENCV", WIDTH, HEIGHT, tuple(intrinsics("OPENCV")))
    csv = folder / "highlights.csv"
    rows = csv.read_text().splitlines()
    out = [rows[0]]
    for row in rows[1:]:
        name, u, v = row.split(",")
        (du, dv), = camera.distort([[float(u), float(v)]])
        # Ignored, a shift of 1e-3 px would leave the ray 5e-6 from its point (depth 4, f 800).
        assert math.hypot(du - float(u), dv - float(v)) > 1e-3
        out.append(f"{name},{float(du)!r},{float(dv)!r}")
    csv.write_text("\n".join(out) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_colmap(folder, csv, light="camera")
    dist, _ = distance_to_rays(scene, SPECULAR)
    assert np.all(dist < 1e-9), dist


@pytest.mark.parametrize("model", ["SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV"])
def test_undistort_inverts_distort(model):
    params = {"SIMPLE_RADIAL": (500.0, 320.0, 240.0, -0.12),
              "RADIAL": (500.0, 320.0, 240.0, -0.1, 0.02),
              "OPENCV": (500.0, 510.0, 320.0, 240.0, -0.1, 0.01, 0.001, -0.002),
              "FULL_OPENCV": (500.0, 510.0, 320.0, 240.0, -0.1, 0.01, 0.001, -0.002, 0.001,
                              0.05, 0.001, 0.0005)}[model]
    cam = ColmapCamera(1, model, 640, 480, params)
    grid = np.stack(np.meshgrid(np.linspace(0, 640, 9), np.linspace(0, 480, 7)), -1)
    ideal = grid.reshape(-1, 2)
    back, ok = cam.undistort(cam.distort(ideal))
    assert ok.all()
    np.testing.assert_allclose(back, ideal, atol=1e-7)


def test_full_opencv_distortion_follows_colmap():
    p = (400.0, 410.0, 300.0, 200.0, 0.1, -0.02, 0.003, 0.001, 0.004, 0.2, -0.01, 0.002)
    cam = ColmapCamera(1, "FULL_OPENCV", 600, 400, p)
    x, y = 0.3, -0.25
    r2 = x * x + y * y
    radial = (1 + 0.1 * r2 - 0.02 * r2**2 + 0.004 * r2**3) / (1 + 0.2 * r2 - 0.01 * r2**2
                                                                + 0.002 * r2**3)
    xd = x * radial + 2 * 0.003 * x * y + 0.001 * (r2 + 2 * x * x)
    yd = y * radial + 2 * 0.001 * x * y + 0.003 * (r2 + 2 * y * y)
    np.testing.assert_allclose(cam.distort([[300 + 400 * x, 200 + 410 * y]]),
                               [[300 + 400 * xd, 200 + 410 * yd]], rtol=1e-14)


def test_distortion_of_a_radial_camera_follows_colmap():
    cam = ColmapCamera(1, "RADIAL", 100, 100, (50.0, 50.0, 50.0, 0.1, 0.01))
    x, y = 0.4, -0.2
    r2 = x * x + y * y
    k = 1 + 0.1 * r2 + 0.01 * r2 * r2
    np.testing.assert_allclose(cam.distort([[50 + 50 * x, 50 + 50 * y]]),
                               [[50 + 50 * x * k, 50 + 50 * y * k]])


def _edit(path: Path, line: int, text: str | None):
    lines = path.read_text().splitlines()
    if text is None:
        del lines[line - 1]
    else:
        lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


# (file, line, new text, field named in the message)
MALFORMED = [
    ("cameras.txt", 4, "1 FISHEYE 640 480 800 320 240", "MODEL"),
    ("cameras.txt", 4, "1 PINHOLE 640 480 800 320 240", "PARAMS"),
    ("cameras.txt", 4, "1 PINHOLE 640x 480 800 790 320 240", "WIDTH"),
    ("cameras.txt", 4, "1 PINHOLE 640 480 -800 790 320 240", "PARAMS.fx"),
    ("cameras.txt", 5, "1 PINHOLE 640 480 800 790 320 240", "CAMERA_ID"),
    ("cameras.txt", 4, "1 PINHOLE", "line"),
    ("images.txt", 4, "7 1 abc 0 0 0 0 4 2 img000.png", "QX"),
    ("images.txt", 4, "7 1 0 0 0 0 0 inf 2 img000.png", "TZ"),
    ("images.txt", 4, "7 0 0 0 0 0 0 4 2 img000.png", "QW QX QY QZ"),
    ("images.txt", 4, "7 1 0 0 0 0 0 4 9 img000.png", "CAMERA_ID"),
    ("images.txt", 4, "7 1 0 0 0 0 0 4 2", "line"),
    ("images.txt", 7, "100.5 200.25", "POINTS2D"),
    ("images.txt", 8, "7 1 0 0 0 0 0 4 2 img009.png", "IMAGE_ID"),
    ("points3D.txt", 3, "10 1.0 nan 0.0 200 100 50 0.5 7 0", "Y"),
    ("points3D.txt", 3, "10 1.0 0.0 0.0 200 100 50 0.5 7", "TRACK"),
    ("points3D.txt", 3, "10 1.0 0.0 0.0 200 100", "line"),
    ("points3D.txt", 4, "10 1.0 0.0 0.0 200 100 50 0.5", "POINT3D_ID"),
    ("highlights.csv", 2, "nowhere.png,10,10", "image"),
    ("highlights.csv", 2, "img000.png,ten,10", "u"),
    ("highlights.csv", 2, "img000.png,10", "row"),
    ("highlights.csv", 2, "img000.png,10,480.5", "u, v"),
    ("highlights.csv", 2, "img000.png,10,1e999", "v"),
]


@pytest.mark.parametrize(("name", "line", "text", "field"), MALFORMED,
                         ids=[f"{m[0]}-{m[3]}-{i}" for i, m in enumerate(MALFORMED)])
def test_malformed_lines_are_named_by_file_line_and_field(model, name, line, text, field):
    path = model / name
    _edit(path, line, text)
    with pytest.raises(ws.SceneError) as info:
        load_colmap(model, model / "highlights.csv", light="camera")
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: {field}: "), message
    assert "\n" not in message


def test_missing_files_and_folders(model, tmp_path):
    with pytest.raises(ws.SceneError, match="no such folder"):
        load_colmap(tmp_path / "nope", None, light="camera")
    (model / "cameras.txt").rename(model / "cameras.bin")
    with pytest.raises(ws.SceneError, match=r"cameras.txt: no such file.*model_converter"):
        load_colmap(model, model / "highlights.csv", light="camera")
    (model / "cameras.bin").rename(model / "cameras.txt")
    with pytest.raises(ws.SceneError, match=r"nope.csv: no such file"):
        load_colmap(model, model / "nope.csv", light="camera")
    with pytest.raises(ws.SceneError, match="^light: missing"):
        load_colmap(model, model / "highlights.csv", light=None)
    with pytest.raises(ws.SceneError, match="^pixel_convention:"):
        load_colmap(model, model / "highlights.csv", light="camera", pixel_convention="centre")


def test_scene_errors_point_back_to_the_highlight_line(model):
    # A directional light along the first ray: no normal satisfies the reflection law there.
    scene = load_colmap(model, model / "highlights.csv", light="camera")
    direction = scene.rays()[1][0]
    with pytest.raises(ws.SceneError, match=r"^specularities\[0\]: .*highlights.csv:\d+\)$"):
        load_colmap(model, model / "highlights.csv", light={"type": "directional",
                                                            "direction": direction.tolist()})


MUTATIONS = st.one_of(
    st.sampled_from(["", "#", "nan", "inf", "-1", "0", "1e309", "1e-320", "abc", "PINHOLE",
                     "OPENCV", ",", "img000.png", "img000.png,1,2", "   ", "\t", "1 2 3"]),
    st.text(max_size=12),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**20), 10**20).map(str),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    name=st.sampled_from(["cameras.txt", "images.txt", "points3D.txt", "highlights.csv"]),
    line=st.integers(0, 40),
    token=st.integers(0, 12),
    mutation=MUTATIONS,
    kind=st.sampled_from(["replace-token", "replace-line", "insert-line", "delete-line"]),
)
def test_mutated_models_give_a_scene_or_a_scene_error(name, line, token, mutation, kind):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "m"
        write_model(folder)
        path = folder / name
        lines = path.read_text().splitlines()
        i = line % (len(lines) + 1)
        if kind == "insert-line" or i == len(lines):
            lines.insert(i, mutation)
        elif kind == "delete-line":
            del lines[i]
        elif kind == "replace-line":
            lines[i] = mutation
        else:
            tokens = lines[i].replace(",", " , ").split()
            if tokens:
                tokens[token % len(tokens)] = mutation
            lines[i] = " ".join(tokens).replace(" , ", ",")
        path.write_text("\n".join(lines) + "\n")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                scene = load_colmap(folder, folder / "highlights.csv", light="camera")
            except ws.SceneError as exc:
                assert "\n" not in str(exc)
            else:
                assert isinstance(scene, ws.Scene)


def test_the_octant_scene_round_trips_through_a_colmap_model(tmp_path):
    # Write the paper's octant (24 cameras P = K [R | t]) as a COLMAP model and read it back.
    from scipy.linalg import rq

    octant = ws.Scene.load(Path(__file__).resolve().parents[1] / "examples" / "scenes" /
                           "octant.json")
    folder = tmp_path / "octant"
    folder.mkdir()
    cameras, images, highlights = [], [], ["image,u,v"]
    def text(*values):
        return " ".join(repr(float(v)) for v in values)

    for i, P in enumerate(octant.cameras):
        K, R = rq(P[:, :3])
        D = np.diag(np.sign(np.diag(K)))
        K, R = K @ D, D @ R
        t = np.linalg.solve(K, P[:, 3])
        K = K / K[2, 2]
        assert abs(K[0, 1]) < 1e-9 * K[0, 0]  # no skew: a PINHOLE camera
        cameras.append(f"{i + 1} PINHOLE 640 480 {text(K[0, 0], K[1, 1], K[0, 2], K[1, 2])}")
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        images += [f"{i + 1} {text(w, x, y, z, *t)} {i + 1} view {i}.png", ""]
    for c, (u, v) in zip(octant.spec_camera, octant.spec_pixel, strict=True):
        highlights.append(f"view {c}.png,{text(u)},{text(v)}")
    points = [f"{k + 1} {text(*p)} 128 128 128 0.5 1 0" for k, p in enumerate(octant.points)]
    for name, lines in (("cameras.txt", cameras), ("images.txt", images),
                        ("points3D.txt", points), ("highlights.csv", highlights)):
        (folder / name).write_text("\n".join(lines) + "\n")
    light = {"type": "directional", "direction": octant.light.vector.tolist()}
    scene = load_colmap(folder, folder / "highlights.csv", light=light)
    o1, d1 = octant.rays()
    o2, d2 = scene.rays()
    np.testing.assert_allclose(o2, o1, atol=1e-9)
    np.testing.assert_allclose(d2, d1, atol=1e-9)
    np.testing.assert_allclose(scene.normals(), octant.normals(), atol=1e-9)
    np.testing.assert_array_equal(scene.points, octant.points)


# -- binary models, COLMAP's folder layout, the object's points and the domain -----------------


def tabletop_model(folder: Path, *, text=True, binary=True, camera_model="PINHOLE"):
    """A shiny ball (radius 0.1) on a table, 24 flash photographs, 5 points on the ball and 600
    on the table and a wall; returns the ids of the ball's points."""
    from warpspec.colmap import ColmapCamera, ColmapImage, quaternion_from_rotation, write_model

    rng = np.random.default_rng(3)
    centre = np.array([0.0, 0.0, 0.1])
    az = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    el = np.radians(np.where(np.arange(24) % 2, 25.0, 45.0))
    cams = centre + 0.6 * np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el),
                                           np.sin(el)])
    params = intrinsics(camera_model)
    camera = ColmapCamera(1, camera_model, WIDTH, HEIGHT, tuple(params))
    up = rng.normal(size=(5, 3))
    up[:, 2] = np.abs(up[:, 2]) + 0.5
    ball = centre + 0.1 * up / np.linalg.norm(up, axis=1, keepdims=True)
    table = np.column_stack([rng.uniform(-1.5, 1.5, (500, 2)), np.zeros(500)])
    table = table[np.linalg.norm(table[:, :2], axis=1) > 0.1]
    wall = np.column_stack([np.full(100, 1.5), rng.uniform(-1.5, 1.5, 100),
                            rng.uniform(0, 1.0, 100)])
    xyz = np.concatenate([ball, table, wall])
    ids = np.arange(100, 100 + len(xyz))
    images, obs, rows = [], [], ["image,u,v,peak,size,score"]
    tracks = [[] for _ in xyz]
    for k, c in enumerate(cams):
        R = look_at(c, centre)
        t = -R @ c
        images.append(ColmapImage(k + 1, tuple(quaternion_from_rotation(R)), tuple(t), 1,
                                  f"photo{k:02d}.jpg"))
        h = (xyz @ R.T + t) @ K_of(camera_model).T
        uv = camera.distort(h[:, :2] / h[:, 2:3])
        seen = np.flatnonzero((h[:, 2] > 0) & (uv[:, 0] > 0) & (uv[:, 0] < WIDTH)
                              & (uv[:, 1] > 0) & (uv[:, 1] < HEIGHT))
        obs.append(np.column_stack([uv[seen], ids[seen]]))
        for j, i in enumerate(seen):
            tracks[i].append((k + 1, j))
        x = centre + 0.1 * (c - centre) / np.linalg.norm(c - centre)  # the flash's highlight
        q = K_of(camera_model) @ (R @ x + t)
        (u, v), = camera.distort((q[:2] / q[2])[None])
        rows.append(f"photo{k:02d}.jpg,{float(u)!r},{float(v)!r},1.0,12,0.6")
    folder.mkdir(parents=True)
    write_model(folder, {1: camera}, images, obs, ids, xyz, np.full((len(xyz), 3), 90),
                rng.uniform(0.2, 1.0, len(xyz)), tracks, text=text, binary=binary)
    (folder.parent / "highlights.csv").write_text("\n".join(rows) + "\n")
    return tuple(int(i) for i in ids[:5]), ball, centre


def test_binary_and_text_models_read_the_same(tmp_path):
    from warpspec.colmap import read_model

    tabletop_model(tmp_path / "sparse" / "0", camera_model="OPENCV")
    folder = tmp_path / "sparse" / "0"
    text = read_model(folder)
    (tmp_path / "bin").mkdir()
    for name in ("cameras.bin", "images.bin", "points3D.bin"):
        (folder / name).rename(tmp_path / "bin" / name)
    binary = read_model(tmp_path / "bin")
    assert text[4] == "text" and binary[4] == "binary"
    assert {k: (c.model, c.width, c.height, c.params) for k, c in text[0].items()} == \
        {k: (c.model, c.width, c.height, c.params) for k, c in binary[0].items()}
    assert text[1].keys() == binary[1].keys()
    for k, im in text[1].items():
        other = binary[1][k]
        assert (im.qvec, im.tvec, im.camera_id, im.name) == (other.qvec, other.tvec,
                                                             other.camera_id, other.name)
        np.testing.assert_array_equal(im.points2d, other.points2d)
    for a, b in zip(text[2], binary[2], strict=True):
        np.testing.assert_array_equal(a, b)
    csv = tmp_path / "sparse" / "highlights.csv"
    s_text = load_colmap(folder, csv, light="camera")
    s_bin = load_colmap(tmp_path / "bin", csv, light="camera")
    np.testing.assert_array_equal(s_text.cameras, s_bin.cameras)
    np.testing.assert_array_equal(s_text.points, s_bin.points)


def test_binary_errors_name_the_file_and_record(tmp_path):
    folder = tmp_path / "m"
    tabletop_model(folder, text=False)
    data = (folder / "images.bin").read_bytes()
    (folder / "images.bin").write_bytes(data[:200])
    with pytest.raises(ws.SceneError, match=r"images.bin, record 1 \(byte \d+\): POINTS2D: "):
        load_colmap(folder, tmp_path / "highlights.csv", light="camera")
    cams = bytearray((folder / "cameras.bin").read_bytes())
    cams[12:16] = (5).to_bytes(4, "little")  # model id 5: OPENCV_FISHEYE
    (folder / "cameras.bin").write_bytes(bytes(cams))
    with pytest.raises(ws.SceneError, match=r"cameras.bin, record 1 \(byte \d+\): MODEL: camera 1 "
                       r"is 'OPENCV_FISHEYE', a fisheye model"):
        load_colmap(folder, tmp_path / "highlights.csv", light="camera")


def test_fisheye_text_camera_is_refused_by_name(model):
    _edit(model / "cameras.txt", 4, "1 OPENCV_FISHEYE 640 480 800 790 320 240 0 0 0 0")
    with pytest.raises(ws.SceneError, match=r"cameras.txt:4: MODEL: camera 1 is 'OPENCV_FISHEYE', "
                       "a fisheye model"):
        load_colmap(model, model / "highlights.csv", light="camera")


@pytest.mark.parametrize("camera_model", ["PINHOLE", "OPENCV"])
def test_the_balls_points_and_a_domain_that_every_ray_enters(tmp_path, camera_model):
    from warpspec.colmap import _ray_box, read_model

    ball_ids, ball, centre = tabletop_model(tmp_path / "sparse" / "0", binary=False,
                                            camera_model=camera_model)
    imported = import_colmap(tmp_path / "sparse", tmp_path / "sparse" / "highlights.csv",
                             light="camera")
    assert imported.model_dir == tmp_path / "sparse" / "0"
    assert imported.point_ids == ball_ids  # not one of the 600 table and wall points
    scene = imported.scene
    lo, hi = scene.domain
    assert np.all(lo <= ball.min(axis=0)) and np.all(hi >= ball.max(axis=0))
    assert np.all(hi - lo < 0.5)  # about the ball (0.2 across), not the table (3 m)
    origins, dirs = scene.rays()
    assert _ray_box(origins, dirs, lo, hi).all()
    # The flash rays all pass through the ball's centre: it lies inside the domain.
    assert np.all((centre > lo) & (centre < hi))
    total = len(read_model(tmp_path / "sparse")[2][0])
    assert load_colmap(tmp_path / "sparse", None, light=None).num_points == total  # no rays


def test_a_sparse_folder_without_a_model_says_where_it_looked(tmp_path):
    (tmp_path / "sparse" / "1").mkdir(parents=True)
    with pytest.raises(ws.SceneError, match=r"no COLMAP model here: expected cameras.txt or "
                       r"cameras.bin, here or in .*sparse/0 \(it holds the folders 1\)"):
        load_colmap(tmp_path / "sparse", None, light=None)


def test_quaternion_round_trip():
    from warpspec.colmap import quaternion_from_rotation

    for angles in ([0.4, -1.1, 2.0], [np.pi, 0, 0], [0, np.pi, 0.001], [3.0, 0.1, -3.1]):
        R = Rotation.from_euler("xyz", angles).as_matrix()
        np.testing.assert_allclose(rotation_from_quaternion(quaternion_from_rotation(R)), R,
                                   atol=1e-12)


def test_object_points_of_a_sphere_that_fills_the_frame_are_kept():
    """A flash on a sphere sends every ray through its centre: the rays' region has no size,
    and the sphere may overfill the frame; its points are kept, the far background not."""
    from warpspec.colmap import select_object_points

    rng = np.random.default_rng(2)
    on_sphere = rng.normal(size=(12, 3))
    on_sphere *= 1.07 / np.linalg.norm(on_sphere, axis=1, keepdims=True)
    far = rng.uniform(-6, 6, size=(40, 3))
    far = far[np.linalg.norm(far, axis=1) > 3.0]
    mask, _ = select_object_points(np.vstack([on_sphere, far]), (np.zeros(3), 1e-4), 1.03)
    assert mask[:12].all() and not mask[12:].any()
