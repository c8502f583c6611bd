"""Pictures: renders of a mesh with its constraints and convergence curves, headless."""

import sys

import numpy as np
import pytest
import trimesh

import warpspec as ws
from warpspec.plots import plot_history, render_mesh, require_matplotlib

pytest.importorskip("matplotlib")

PNG = b"\x89PNG\r\n\x1a\n"


def png_size(path):
    """Width and height from the IHDR chunk of a PNG file."""
    data = path.read_bytes()
    assert data[:8] == PNG
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.fixture
def cap():
    """One eighth of the unit sphere (the octant patch), with its three corner points."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    keep = np.all(sphere.triangles_center > 0, axis=1)
    mesh = sphere.copy()
    mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()
    return mesh


def history(n=50, *, misses=0, points=True):
    return [
        {"iteration": i, "normal_error": 0.17 * np.exp(-i / 10) + 1e-4,
         "point_error": 0.07 * np.exp(-i / 20) if points else float("nan"),
         "energy_normal": 0.5 * np.exp(-i / 10), "energy_point": 1e-3 * np.exp(-i / 20),
         "energy_smooth": 1.6 - 0.001 * i, "energy_total": 0.5 * np.exp(-i / 10) + 0.016,
         "active": 24 - misses, "misses": misses, "seconds": 0.01 * i}
        for i in range(n + 1)
    ]


def test_render_writes_a_png_with_the_views_side_by_side(cap, tmp_path):
    rng = np.random.default_rng(1)
    hits = cap.vertices[rng.choice(len(cap.vertices), 24, replace=False)]
    normals = hits / np.linalg.norm(hits, axis=1, keepdims=True)
    hits[3] = np.nan  # a missed ray is skipped
    path = tmp_path / "render.png"
    render_mesh(cap, path, points=np.eye(3), hits=hits, normals=normals, views=3)
    width, height = png_size(path)
    assert width > 2.5 * height  # three square-ish views in a row
    assert path.stat().st_size > 10_000
    one = tmp_path / "one.png"
    render_mesh(cap, one, views=1)
    w1, _ = png_size(one)
    assert w1 < width / 2


def test_render_marks_faces_seen_from_inside(cap, tmp_path):
    # Seen from its cameras, the patch with its faces flipped shows the "inside" colour.
    from PIL import Image

    cameras = 3.0 * np.array([[1.0, 0.8, 1.2], [1.2, 1.0, 0.7], [0.6, 1.1, 1.0]])
    outside, inside = tmp_path / "out.png", tmp_path / "in.png"
    render_mesh(cap, outside, cameras=cameras, views=1)
    flipped = cap.copy()
    flipped.invert()
    render_mesh(flipped, inside, cameras=cameras, views=1)

    def orange_fraction(path):
        rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
        return np.mean((rgb[..., 0] > rgb[..., 2] + 60) & (rgb[..., 0] > 120))

    assert orange_fraction(outside) < 0.01
    assert orange_fraction(inside) > 0.05


def test_plot_history_writes_four_panels(tmp_path):
    path = tmp_path / "history.png"
    plot_history(history(), path)
    width, height = png_size(path)
    assert width > height > 500
    # No point constraints and some misses still plot.
    plot_history(history(10, misses=3, points=False), tmp_path / "partial.png")
    assert png_size(tmp_path / "partial.png")[0] == width


def test_bad_arguments_are_scene_errors(cap, tmp_path):
    with pytest.raises(ws.InputError, match="^history:"):
        plot_history([], tmp_path / "x.png")
    with pytest.raises(ws.InputError, match="^views:"):
        render_mesh(cap, tmp_path / "x.png", views=0)
    with pytest.raises(ws.InputError, match="^mesh: has no faces"):
        render_mesh(trimesh.Trimesh(), tmp_path / "x.png")
    with pytest.raises(ws.InputError, match=r"^hits: expected an array of shape \(n, 3\)"):
        render_mesh(cap, tmp_path / "x.png", hits=np.zeros((4, 2)))
    assert not (tmp_path / "x.png").exists()


def test_missing_matplotlib_gives_a_clear_message(cap, tmp_path, monkeypatch):
    for name in list(sys.modules):
        if name == "matplotlib" or name.startswith("matplotlib."):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    with pytest.raises(ws.InputError, match=r"^--render: needs matplotlib; install it with: "
                                            r"pip install 'warpspec\[plot\]'$"):
        require_matplotlib("--render")
    with pytest.raises(ws.InputError, match="^render_mesh: needs matplotlib"):
        render_mesh(cap, tmp_path / "x.png")
    with pytest.raises(ws.InputError, match="^plot_history: needs matplotlib"):
        plot_history(history(), tmp_path / "x.png")
