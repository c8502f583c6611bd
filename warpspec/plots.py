"""Pictures of a reconstruction: views of the mesh with its constraints, convergence curves.

matplotlib is an optional extra (``pip install 'warpspec[plot]'``); it is imported only when a
picture is drawn, and drawn without pyplot (a ``Figure`` on the Agg canvas), so these functions
run headless and leave the caller's matplotlib backend alone.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["plot_history", "render_mesh", "require_matplotlib"]

INSTALL_HINT = "install it with: pip install 'warpspec[plot]'"

# Colours: the surface seen from its outside (phi > 0) and from its inside, the constraints.
_FRONT = np.array([0.62, 0.72, 0.86])
_BACK = np.array([0.93, 0.62, 0.38])
_POINT = "#d62728"
_HIT = "#1f3f99"
_NORMAL = "#2ca02c"


def require_matplotlib(what: str = "plots") -> None:
    """Check that matplotlib can be imported.

    Args:
        what: The feature that needs it, for the message (``"--render"``).

    Raises:
        InputError: ``"<what>: needs matplotlib; install it with: pip install 'warpspec[plot]'"``.
    """
    _figure_class(what)


def _figure_class(what: str):
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError(f"{what}: needs matplotlib; {INSTALL_HINT}") from None
    return Figure


def _rows(value: Any, field: str, n: int | None = None) -> np.ndarray:
    """An ``(k, 3)`` float array (``None``: empty)."""
    if value is None:
        return np.zeros((0, 3))
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{field}: expected an array of shape (n, 3)") from None
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{field}: expected an array of shape (n, 3), got {arr.shape}")
    if n is not None and len(arr) != n:
        raise InputError(f"{field}: expected {n} rows (one per hit), got {len(arr)}")
    return arr


def _views(front: np.ndarray | None, label: str, count: int) -> list[tuple[float, float, str]]:
    """``(elevation, azimuth, label)`` of each view, the first from direction ``front``."""
    if front is None:
        elev, azim = 25.0, -60.0
    else:
        elev = math.degrees(math.asin(float(np.clip(front[2], -1.0, 1.0))))
        azim = math.degrees(math.atan2(front[1], front[0]))
    views = [(elev, azim, label)]
    tilt = float(np.clip(elev + 20.0, -80.0, 80.0))
    views.append((tilt, azim - 60.0, "oblique, left"))
    views.append((tilt, azim + 60.0, "oblique, right"))
    views.append((float(np.clip(elev - 70.0, -89.0, 89.0)), azim, "grazing"))
    views.append((elev, azim + 180.0, "back"))
    views.append((89.0, -90.0, "top (+z)"))
    return views[:count]


def render_mesh(
    mesh,
    path: str | os.PathLike,
    *,
    points: Any = None,
    hits: Any = None,
    normals: Any = None,
    cameras: Any = None,
    views: int = 3,
    title: str | None = None,
    dpi: int = 110,
) -> None:
    """Draw views of a mesh with its constraints and save the picture.

    The first view looks from the cameras (from the mean direction toward them) when they are
    given, else along the surface's mean normal; the others are oblique. The surface is shaded
    by a light that follows the viewer; faces seen from the front (``phi > 0``, the cameras'
    side) are blue-grey, faces seen from behind are orange, so a surface that faces away from
    its cameras shows at once. The point constraints are red dots, the ray
    intersections dark blue dots and the constraint normals green arrows from the
    intersections. The markers are drawn over the surface, even where it hides them.

    Args:
        mesh: A ``trimesh.Trimesh`` (anything with ``vertices``, ``faces``, ``face_normals``).
        path: The picture to write; the format follows the extension (PNG, PDF, SVG...).
        points: Point constraints, ``(K, 3)``.
        hits: Where the specular rays meet the surface, ``(M, 3)``; rows with NaN (missed
            rays) are skipped.
        normals: The constraint normals at ``hits``, ``(M, 3)``.
        cameras: Camera centres, ``(C, 3)``: the first view looks from their side.
        views: Number of views side by side, 1 to 6.
        title: Title over the views.
        dpi: Resolution of a raster picture.

    Raises:
        InputError: If matplotlib is missing, the mesh has no faces, or an array is malformed.
    """
    Figure = _figure_class("render_mesh")
    if isinstance(views, bool) or not isinstance(views, int) or not 1 <= views <= 6:
        raise InputError(f"views: expected an integer from 1 to 6, got {views!r}")
    try:
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except AttributeError:
        raise InputError(f"mesh: expected a trimesh.Trimesh, got {type(mesh).__name__}") from None
    if len(faces) == 0:
        raise InputError("mesh: has no faces, nothing to render")
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    triangles = vertices[faces]
    face_normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    area = np.linalg.norm(face_normals, axis=1, keepdims=True)
    face_normals = np.divide(face_normals, area, out=np.zeros_like(face_normals),
                             where=area > 0)
    mean = (face_normals * area).sum(axis=0)
    mean_normal = mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-9 * area.sum() \
        else None

    points = _rows(points, "points")
    hits = _rows(hits, "hits")
    normals = _rows(normals, "normals", len(hits) if normals is not None and len(hits) else None)
    ok = np.all(np.isfinite(hits), axis=1)
    if len(normals):
        ok &= np.all(np.isfinite(normals), axis=1)
        normals = normals[ok]
    hits = hits[ok]

    everything = np.vstack([vertices, points, hits])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    centre = 0.5 * (lo + hi)
    front, front_label = mean_normal, "along the mean normal"
    cameras = _rows(cameras, "cameras")
    cameras = cameras[np.all(np.isfinite(cameras), axis=1)]
    if len(cameras):
        toward = cameras - centre
        toward /= np.maximum(np.linalg.norm(toward, axis=1, keepdims=True), 1e-300)
        mean = toward.sum(axis=0)
        if np.linalg.norm(mean) > 1e-6 * len(toward):
            front, front_label = mean / np.linalg.norm(mean), "from the cameras"
    radius = 0.5 * float(np.max(hi - lo)) or 1.0
    arrow = 0.15 * radius

    fig = Figure(figsize=(4.0 * views, 4.4), dpi=dpi, layout="constrained")
    for k, (elev, azim, label) in enumerate(_views(front, front_label, views)):
        ax = fig.add_subplot(1, views, k + 1, projection="3d", computed_zorder=False)
        ax.view_init(elev=elev, azim=azim)
        e, a = math.radians(elev), math.radians(azim)
        eye = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        facing = face_normals @ eye
        # Light from above and left of the viewer; |n.l| lights the back faces too.
        right = np.cross([0.0, 0.0, 1.0], eye)
        right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-6 \
            else np.array([0.0, 1.0, 0.0])
        light = eye + 0.7 * np.cross(eye, right) - 0.6 * right
        light /= np.linalg.norm(light)
        shade = 0.3 + 0.7 * np.abs(face_normals @ light)
        base = np.where(facing[:, None] >= 0, _FRONT, _BACK)
        colours = np.clip(base * shade[:, None], 0.0, 1.0)
        surface = Poly3DCollection(triangles, facecolors=colours, edgecolors="none",
                                   linewidths=0.0, zorder=1)
        ax.add_collection3d(surface)
        if len(normals):
            ax.quiver(hits[:, 0], hits[:, 1], hits[:, 2], normals[:, 0], normals[:, 1],
                      normals[:, 2], length=arrow, normalize=True, color=_NORMAL,
                      linewidth=1.2, arrow_length_ratio=0.3, zorder=2)
        if len(hits):
            ax.scatter(hits[:, 0], hits[:, 1], hits[:, 2], s=10, color=_HIT, depthshade=False,
                       zorder=3)
        if len(points):
            ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=36, color=_POINT,
                       edgecolors="black", linewidths=0.6, depthshade=False, zorder=4)
        for axis, c in zip("xyz", centre, strict=True):
            getattr(ax, f"set_{axis}lim")(c - radius, c + radius)
            getattr(ax, f"set_{axis}label")(axis, labelpad=-10)
        ax.set_box_aspect((1.0, 1.0, 1.0))
        ax.tick_params(labelsize=6, pad=-2)
        ax.set_title(f"{label}\nelev {elev:.0f}, azim {azim:.0f}", fontsize=8)

    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(color=_FRONT, label="surface, outside"),
               Patch(color=_BACK, label="surface, inside")]
    if len(points):
        handles.append(Line2D([], [], marker="o", ls="", color=_POINT, mec="black",
                              label=f"points S ({len(points)})"))
    if len(hits):
        handles.append(Line2D([], [], marker="o", ls="", ms=4, color=_HIT,
                              label=f"ray intersections ({len(hits)})"))
    if len(normals):
        handles.append(Line2D([], [], color=_NORMAL, label="constraint normals N"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8,
               frameon=False)
    fig.suptitle(title or f"{len(faces)} faces", fontsize=10)
    fig.savefig(os.fspath(path))


def _column(history: Sequence[Mapping], key: str) -> np.ndarray:
    out = np.full(len(history), np.nan)
    for i, row in enumerate(history):
        value = row.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            out[i] = float(value)
    return out


def _curve(ax, x: np.ndarray, y: np.ndarray, label: str, **style) -> bool:
    """Plot the finite part of a curve; say whether anything was drawn."""
    ok = np.isfinite(y)
    if not ok.any():
        return False
    ax.plot(x[ok], y[ok], label=label, **style)
    return True


def _log_if_positive(ax, *columns: np.ndarray) -> None:
    values = np.concatenate([c[np.isfinite(c)] for c in columns])
    if len(values) and np.all(values > 0) and values.max() > 20 * values.min():
        ax.set_yscale("log")


def plot_history(
    history: Sequence[Mapping], path: str | os.PathLike, *, title: str | None = None,
    dpi: int = 110,
) -> None:
    """Draw the convergence curves of a run and save the picture.

    Four panels against the iteration: the mean normal error ``1 - N.n`` over the active rays
    (the paper's Figure 5a), the mean point error ``|phi(S)|`` in voxel widths (Figure 5b), the
    energies (``E_N``, ``E_P``, ``alpha E_S`` and their total) and the number of active and
    missed rays. A logarithmic axis is used where the values are positive and span a wide range.

    Args:
        history: One dict per recorded iteration, as ``Result.history``.
        path: The picture to write; the format follows the extension.
        title: Title over the panels.
        dpi: Resolution of a raster picture.

    Raises:
        InputError: If matplotlib is missing or the history is empty or malformed.
    """
    Figure = _figure_class("plot_history")
    if isinstance(history, Mapping) or not isinstance(history, Sequence) or not history:
        raise InputError("history: expected a non-empty list of per-iteration dicts")
    if not all(isinstance(row, Mapping) for row in history):
        raise InputError("history: every entry must be a dict of measures")
    it = _column(history, "iteration")
    if not np.all(np.isfinite(it)):
        it = np.arange(len(history), dtype=np.float64)

    fig = Figure(figsize=(10.0, 7.0), dpi=dpi)
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.08, top=0.91, wspace=0.24, hspace=0.2)
    axes = fig.subplots(2, 2, sharex=True)

    ax = axes[0, 0]
    normal = _column(history, "normal_error")
    if not _curve(ax, it, normal, "mean 1 - N.n", color="#1f77b4"):
        ax.text(0.5, 0.5, "no active rays", ha="center", va="center", transform=ax.transAxes)
    _log_if_positive(ax, normal)
    ax.set_title("normal error (active rays)", fontsize=10)
    ax.set_ylabel("mean 1 - N.n")

    ax = axes[0, 1]
    point = _column(history, "point_error")
    if not _curve(ax, it, point, "mean |phi(S)|", color="#d62728"):
        ax.text(0.5, 0.5, "no point constraints", ha="center", va="center",
                transform=ax.transAxes)
    _log_if_positive(ax, point)
    ax.set_title("point error", fontsize=10)
    ax.set_ylabel("mean |phi(S)| (voxels)")

    ax = axes[1, 0]
    e_n = _column(history, "energy_normal")
    e_p = _column(history, "energy_point")
    total = _column(history, "energy_total")
    smooth = total - e_n - e_p
    drawn = [c for c, label, colour in ((e_n, "E_N (normal)", "#1f77b4"),
                                        (e_p, "E_P (points)", "#d62728"),
                                        (smooth, "alpha E_S (smoothness)", "#9467bd"),
                                        (total, "total", "black"))
             if _curve(ax, it, c, label, color=colour, lw=1.2,
                       ls="--" if label == "total" else "-")]
    if drawn:
        _log_if_positive(ax, *drawn)
        ax.legend(fontsize=8)
    ax.set_title("energies", fontsize=10)
    ax.set_xlabel("iteration")

    ax = axes[1, 1]
    misses = _column(history, "misses")
    active = _column(history, "active")
    _curve(ax, it, active, "active rays", color="#2ca02c", drawstyle="steps-post")
    _curve(ax, it, misses, "missed rays", color="#ff7f0e", drawstyle="steps-post")
    ax.set_ylim(bottom=-0.5)
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.legend(fontsize=8)
    ax.set_title("specular rays", fontsize=10)
    ax.set_xlabel("iteration")

    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
        if ax.get_yscale() == "linear":
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useMathText=True)
    fig.suptitle(title or f"convergence over {int(np.nanmax(it))} iterations", fontsize=11)
    fig.savefig(os.fspath(path))
