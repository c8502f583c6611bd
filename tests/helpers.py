"""Small grid helpers shared by the tests."""

import numpy as np

from warpspec.grid import Grid


def cube_grid(n: int, lo: float = -1.0, hi: float = 1.0) -> Grid:
    """A cubic grid with ``n`` cells per side over ``[lo, hi]^3``."""
    return Grid.from_bounds(np.full(3, lo), np.full(3, hi), resolution=n)


def sphere_sdf(grid: Grid, centre, radius: float) -> np.ndarray:
    """Exact signed distance to a sphere, float64."""
    x, y, z = grid.coordinates()
    c = np.asarray(centre, dtype=float)
    return np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) - radius


def interior(a: np.ndarray, width: int) -> np.ndarray:
    """The array without ``width`` nodes at every face."""
    w = width
    return a[w:-w, w:-w, w:-w]


def turned(data: dict, rotation) -> dict:
    """A scene dictionary turned by ``rotation`` (3x3) about the origin.

    Cameras, lights and points turn with it; the domain becomes the box round the turned
    one's corners (larger, unless the turn maps the axes onto each other).
    """
    import copy

    R = np.asarray(rotation, dtype=np.float64)
    out = copy.deepcopy(data)
    back = np.eye(4)
    back[:3, :3] = R.T  # a world point x' of the turned scene was R^T x' before

    def light(spec: dict) -> dict:
        return {k: (list(R @ np.asarray(v, dtype=np.float64))
                    if k in ("direction", "position") else v) for k, v in spec.items()}

    for camera in out["cameras"]:
        camera["P"] = (np.asarray(camera["P"], dtype=np.float64) @ back).tolist()
        if "light" in camera:
            camera["light"] = light(camera["light"])
    if "light" in out:
        out["light"] = light(out["light"])
    out["points"] = (np.asarray(out["points"], dtype=np.float64).reshape(-1, 3) @ R.T).tolist()
    lo, hi = np.asarray(out["domain"]["min"]), np.asarray(out["domain"]["max"])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]) @ R.T
    out["domain"] = {"min": corners.min(axis=0).tolist(), "max": corners.max(axis=0).tolist()}
    return out


def points_moved(scene, sigma_voxels: float, *, seed: int = 77):
    """``scene`` (a :class:`warpspec.Scene`) with its points moved by Gaussian noise, per axis,
    of ``sigma_voxels`` voxel widths at resolution 64; a new scene."""
    import warpspec as ws

    data = scene.to_dict()
    h = float(np.max(np.subtract(scene.domain[1], scene.domain[0]))) / 64
    pts = np.asarray(scene.points, dtype=np.float64)
    noise = sigma_voxels * h * np.random.default_rng(seed).standard_normal(pts.shape)
    data["points"] = (pts + noise).tolist()
    return ws.Scene.from_dict(data)


def highlights_moved(scene, every: int, shift=(1.5, -1.0)):
    """``scene`` with every ``every``-th highlight's pixel moved by ``shift`` (1.8 px by
    default); the new scene and which highlights moved ``(M,)``."""
    import warpspec as ws

    data = scene.to_dict()
    moved = np.zeros(len(data["specularities"]), dtype=bool)
    moved[::every] = True
    for i in np.flatnonzero(moved):
        u, v = data["specularities"][i]["pixel"]
        data["specularities"][i]["pixel"] = [u + shift[0], v + shift[1]]
    return ws.Scene.from_dict(data), moved
