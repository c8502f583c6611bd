"""Property-based tests of warpspec.scene: any input gives a Scene or a SceneError."""

from __future__ import annotations

import copy
import json
import math
import os
import tempfile
import warnings

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from warpspec.errors import SceneError
from warpspec.scene import Scene, SceneWarning

SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
vec3 = st.lists(finite, min_size=3, max_size=3)


@st.composite
def cameras(draw):
    """A camera on a sphere around the origin, looking at it."""
    theta = draw(st.floats(0.0, 2.0 * math.pi))
    z = draw(st.floats(-0.8, 0.8))
    radius = draw(st.floats(3.0, 20.0))
    centre = radius * np.array([math.cos(theta), math.sin(theta), z])
    forward = -centre / np.linalg.norm(centre)
    x = np.cross(forward, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(forward, x), forward])
    f = draw(st.floats(100.0, 2000.0))
    K = np.array([[f, 0.0, 320.0], [0.0, f, 240.0], [0.0, 0.0, 1.0]])
    P = K @ np.hstack([R, (-R @ centre)[:, None]])
    if draw(st.booleans()):
        P = -P
    return {"P": P.tolist()}


lights = st.one_of(
    st.builds(lambda d: {"type": "directional", "direction": d}, vec3),
    st.builds(lambda p: {"type": "point", "position": p}, vec3),
    st.just({"type": "camera"}),
)


@st.composite
def scene_dicts(draw):
    """A scene dict that is valid unless a drawn light vector happens to be zero."""
    cams = draw(st.lists(cameras(), min_size=1, max_size=4))
    if draw(st.booleans()):
        cams[0]["light"] = draw(lights)
    n_spec = draw(st.integers(0, 6))
    specs = [
        {
            "camera": draw(st.integers(0, len(cams) - 1)),
            "pixel": [draw(st.floats(0.0, 640.0)), draw(st.floats(0.0, 480.0))],
        }
        for _ in range(n_spec)
    ]
    points = draw(st.lists(vec3, min_size=0 if n_spec else 1, max_size=5))
    data = {"format": "warpspec-scene", "version": 1, "cameras": cams, "light": draw(lights)}
    if specs or draw(st.booleans()):
        data["specularities"] = specs
    if points or draw(st.booleans()):
        data["points"] = points
    if draw(st.booleans()):
        lo = draw(vec3)
        data["domain"] = {"min": lo, "max": [v + draw(st.floats(0.1, 5.0)) for v in lo]}
    return data


junk = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(),
        st.integers(min_value=10**18, max_value=10**400) | st.integers(max_value=-(10**18)),
        st.floats(),  # includes NaN and infinities
        st.text(max_size=8),
        st.sampled_from(["directional", "point", "camera", "P", "min", "warpspec-scene"]),
    ),
    lambda children: (
        st.lists(children, max_size=5)
        | st.dictionaries(
            st.text(max_size=6) | st.sampled_from(["type", "P", "camera"]), children, max_size=4
        )
    ),
    max_leaves=12,
)


def paths(node, prefix=()):
    """Every path (sequence of keys and indices) into a nested dict/list."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from paths(value, (*prefix, i))


def get(node, path):
    for key in path:
        node = node[key]
    return node


@st.composite
def mutated_scene_dicts(draw):
    """A valid scene dict with a few random mutations: drop, replace, swap type, NaN..."""
    data = json.loads(json.dumps(draw(scene_dicts())))  # private copy: mutate freely
    for _ in range(draw(st.integers(1, 3))):
        all_paths = list(paths(data))
        path = draw(st.sampled_from(all_paths))
        if not path:
            if draw(st.booleans()):
                return draw(junk)
            continue
        parent, key = get(data, path[:-1]), path[-1]
        action = draw(st.sampled_from(["drop", "junk", "nan", "wrap", "index", "shrink"]))
        if action == "drop":
            del parent[key]
        elif action == "junk":
            parent[key] = draw(junk)
        elif action == "nan":
            parent[key] = draw(st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -0.0]))
        elif action == "wrap":
            parent[key] = [parent[key]] if draw(st.booleans()) else {"x": parent[key]}
        elif action == "index":
            parent[key] = draw(st.sampled_from([-1, -(10**30), 10**30, 2**63, 4, True, 1.5]))
        elif isinstance(parent[key], list) and parent[key]:
            parent[key] = parent[key][:-1]
        else:
            parent[key] = str(parent[key])[:20]
    return data


def exercise(scene: Scene) -> None:
    """Every query of a valid scene either works or raises SceneError."""
    origins, dirs = scene.rays()
    assert np.all(np.isfinite(origins)) and np.all(np.isfinite(dirs))
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    normals = scene.normals(origins + 2.0 * dirs)
    assert np.all(np.isfinite(normals))
    scene.ray_lights()
    scene.camera_centres()
    try:
        lo, hi = scene.bounds()
        assert np.all(hi > lo)
    except SceneError:
        pass
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene.check()


@SETTINGS
@given(scene_dicts())
def test_valid_scene_dicts_load_and_round_trip(data):
    before = copy.deepcopy(data)
    try:
        scene = Scene.from_dict(data)
    except SceneError as exc:
        # Only a drawn zero light vector makes a generated scene invalid.
        assert "non-zero vector" in str(exc)
        return
    assert data == before
    exercise(scene)
    again = Scene.from_dict(json.loads(json.dumps(scene.to_dict())))
    for name in ("cameras", "spec_camera", "spec_pixel", "points"):
        np.testing.assert_array_equal(getattr(again, name), getattr(scene, name))
    assert again.light == scene.light and again.camera_lights == scene.camera_lights
    assert again.to_dict() == scene.to_dict()


@SETTINGS
@given(mutated_scene_dicts())
def test_mutated_scene_dicts_give_a_scene_or_a_scene_error(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = Scene.from_dict(data)
        except SceneError as exc:
            message = str(exc)
            assert "\n" not in message and ": " in message
            event("SceneError")
            return
    event("valid scene")
    exercise(scene)


wild = st.floats(allow_nan=False, allow_infinity=False)  # any finite, 1e308 and subnormals too
wild3 = st.lists(wild, min_size=3, max_size=3)


@st.composite
def extreme_scene_dicts(draw):
    """Structurally valid scenes whose numbers take any finite value."""
    n_cams = draw(st.integers(1, 3))
    wild_matrix = st.lists(st.lists(wild, min_size=4, max_size=4), min_size=3, max_size=3)
    cams = [
        {"P": draw(wild_matrix)} if draw(st.booleans()) else draw(cameras()) for _ in range(n_cams)
    ]
    for cam in cams:  # scale a sane camera by any factor, or shift its centre far away
        if draw(st.booleans()):
            P = np.array(cam["P"])
            with np.errstate(all="ignore"):
                P *= draw(st.floats(1e-300, 1e300))
                P[:, 3] *= draw(st.floats(1e-10, 1e10))
            cam["P"] = P.tolist()
    specs = [
        {"camera": draw(st.integers(0, n_cams - 1)), "pixel": [draw(wild), draw(wild)]}
        for _ in range(draw(st.integers(0, 3)))
    ]
    light = draw(
        st.one_of(
            st.builds(lambda d: {"type": "directional", "direction": d}, wild3),
            st.builds(lambda p: {"type": "point", "position": p}, wild3),
            st.just({"type": "camera"}),
        )
    )
    data = {
        "format": "warpspec-scene",
        "version": 1,
        "cameras": cams,
        "light": light,
        "specularities": specs,
        "points": draw(st.lists(wild3, max_size=4)),
    }
    if draw(st.booleans()):
        data["domain"] = {"min": draw(wild3), "max": draw(wild3)}
    return data


@SETTINGS
@given(extreme_scene_dicts())
def test_extreme_finite_numbers_give_a_scene_or_a_scene_error(data):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no overflow noise from numpy either
        try:
            scene = Scene.from_dict(data)
        except SceneError as exc:
            event(f"SceneError on {str(exc).split(':')[0].split('[')[0]}")
            return
        event("valid scene")
        exercise(scene)


@SETTINGS
@given(junk)
def test_junk_is_a_scene_error(data):
    try:
        Scene.from_dict(data)
    except SceneError:
        return
    raise AssertionError("junk made a valid scene")


@SETTINGS
@given(scene_dicts(), st.data())
def test_damaged_json_text_gives_a_scene_or_a_scene_error(data, draw):
    text = json.dumps(data)
    start = draw.draw(st.integers(0, len(text)))
    stop = draw.draw(st.integers(start, min(len(text), start + 5)))
    text = text[:start] + draw.draw(st.text(max_size=4)) + text[stop:]
    fd, name = tempfile.mkstemp(suffix=".json")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", errors="surrogatepass") as f:
            f.write(text)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                scene = Scene.load(name)
            except SceneError:
                return
        exercise(scene)
    finally:
        os.unlink(name)
