"""Starting surfaces, as strategies: each fills a workspace's level set before the flow.

- :class:`PaperStart`: the paper's plane through the points, bent by ``bulge`` (eq. 23).
- :class:`HeightStart`: that start, refined by a polynomial height field over the plane
  fitted to the points and to the normals where the rays meet it.
- :class:`ImplicitFit`: the default, any shape and topology (:mod:`warpspec.implicit`).
- :class:`GivenStart`: a level set handed in (``phi0=``, a saved level set).

:func:`make_start` builds one from the options of :class:`~warpspec.solver.Reconstructor`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from ..errors import InputError, SceneError
from ..geometry import best_fit_plane, plane_frame
from ..grid import Grid
from ..implicit import FitReport, ImplicitStart
from ..initial import fit_height_field
from ..kernels.start_fields import launch_bend, launch_blend, launch_height_field, launch_plane
from ..scene import Scene
from .workspace import Workspace

__all__ = [
    "GivenStart",
    "HeightStart",
    "ImplicitFit",
    "PaperStart",
    "Start",
    "StartOutcome",
    "initial_plane",
    "make_start",
]


@dataclass(repr=False)
class StartOutcome:
    """What a start leaves besides the level set in the workspace.

    Attributes:
        bent: Host copy of the paper's start (the plane, bent), or of the start itself.
        initial: Host copy of the level set the flow begins from.
        report: The implicit start's fit (its rejected highlights), else ``None``.
        keep: Indices of the rays the flow uses (``None``: all of them).
    """

    bent: np.ndarray
    initial: np.ndarray
    report: FitReport | None = None
    keep: np.ndarray | None = None

    def __repr__(self) -> str:
        kept = "all rays" if self.keep is None else f"{len(self.keep)} rays kept"
        return f"StartOutcome({'x'.join(map(str, self.initial.shape))}, {kept})"


class Start:
    """A starting surface: :meth:`build` fills ``ws.phi`` (redistanced) for the flow."""

    def build(self, scene: Scene, ws: Workspace) -> StartOutcome:
        """Fill ``ws.phi`` with the start and say what else it found."""
        raise NotImplementedError

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in vars(self).items()
                           if not isinstance(v, np.ndarray))
        return f"{type(self).__name__}({fields})"


def initial_plane(scene: Scene, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """The plane the paper starts from: a point on it and its unit normal toward the cameras.

    Least squares through the points when there are three or more that are not collinear;
    otherwise through their centroid (the domain's centre without points) with the mean of
    the constraint normals as its normal.
    """
    points = scene.points
    centres = scene.camera_centres()
    if len(points):
        centroid, axes = best_fit_plane(points)
    else:
        centroid, axes = grid.origin + 0.5 * (grid.upper - grid.origin), None
    normal = None if axes is None else axes[2]
    if normal is None:
        if scene.num_specularities:
            origins, dirs = scene.rays()
            # Where a ray passes closest to the centroid stands in for its unknown depth.
            t = np.einsum("ij,ij->i", centroid - origins, dirs)
            normal = scene.normals(origins + t[:, None] * dirs).mean(axis=0)
        else:
            normal = (centres - centroid).mean(axis=0)
        if not np.linalg.norm(normal) > 1e-12:
            raise SceneError(
                "points: cannot place the initial plane: fewer than three non-collinear points "
                "and no constraint normals to orient it; add points or specularities"
            )
    normal = normal / np.linalg.norm(normal)
    if scene.num_specularities:
        toward = centres[np.unique(scene.spec_camera)] - centroid
    else:
        toward = centres - centroid
    if np.sum(toward @ normal) < 0:
        normal = -normal
    return centroid, normal


class PaperStart(Start):
    """The paper's start: the plane through the points, bent toward the cameras (eq. 23).

    Args:
        bulge: Bending ``c``: a positive value moves the plane toward the cameras by ``c``
            times the distance to the nearest point.
        bulge_cap: Cap on that distance, in voxel widths (``None``: no cap).
    """

    def __init__(self, *, bulge: float = 0.0, bulge_cap: float | None = None) -> None:
        self.bulge = bulge
        self.bulge_cap = bulge_cap

    def _plane(self, scene: Scene, ws: Workspace) -> tuple[np.ndarray, np.ndarray]:
        h = ws.grid.spacing
        point, normal = initial_plane(scene, ws.grid)
        launch_plane(ws.phi, origin=ws.origin, spacing=h, point=tuple(point),
                     normal=tuple(normal))
        if self.bulge != 0.0 and scene.num_points > 0:
            cap = None if self.bulge_cap is None else self.bulge_cap * h
            ws.redistancer.point_distance(ws.points, ws.origin, ws.owner_dist, cap=cap)
            launch_bend(ws.phi, ws.owner_dist, ws.tmp, spacing=h, c=self.bulge)
            ws.swap()
            ws.redistancer.reinitialize(ws.phi)
        return point, normal

    def build(self, scene: Scene, ws: Workspace) -> StartOutcome:
        """Fill ``ws.phi`` with the plane, bent."""
        self._plane(scene, ws)
        bent = ws.phi.numpy().copy()
        return StartOutcome(bent=bent, initial=bent.copy())


class HeightStart(PaperStart):
    """The paper's start refined by a height field fitted to the points and the normals.

    The normals are taken where the rays meet the current start; the field is re-intersected
    and refitted ``fit_iterations`` times, its degree rising from 2 (a gentle quadric first:
    slopes read where the rays meet a poor start sit in the wrong places, and a high degree
    overfits them) to ``fit_degree``.

    Args:
        bulge: As :class:`PaperStart`.
        bulge_cap: As :class:`PaperStart`.
        fit_iterations: Rounds of the fit (0: the paper's start unchanged).
        fit_degree: Highest total degree of the height field's polynomial.
    """

    def __init__(self, *, bulge: float = 0.0, bulge_cap: float | None = None,
                 fit_iterations: int = 5, fit_degree: int = 4) -> None:
        super().__init__(bulge=bulge, bulge_cap=bulge_cap)
        self.fit_iterations = fit_iterations
        self.fit_degree = fit_degree

    def build(self, scene: Scene, ws: Workspace) -> StartOutcome:
        """Fill ``ws.phi`` with the bent plane, then refine it by the height-field fit."""
        point, normal = self._plane(scene, ws)
        bent = ws.phi.numpy().copy()
        if self.fit_iterations and scene.num_specularities:
            self._fit(scene, ws, point, normal)
        return StartOutcome(bent=bent, initial=ws.phi.numpy().copy())

    def _fit(self, scene: Scene, ws: Workspace, point: np.ndarray, normal: np.ndarray) -> None:
        frame = plane_frame(normal)
        scale = 0.5 * float(np.max(ws.grid.upper - ws.grid.origin))
        previous, fitted = ws.good, ws.tmp
        ws.intersect()  # each accepted round ends with the rays intersected again
        changed = False
        for round_ in range(self.fit_iterations):
            ok = ws.active.numpy() == 1
            if ok.sum() < 3:
                break
            fit = fit_height_field(point, frame, scale, scene.points,
                                   ws.hits.numpy()[ok].astype(np.float64),
                                   ws.normals.numpy()[ok].astype(np.float64),
                                   degree=min(self.fit_degree, 2 + round_))
            launch_height_field(
                fitted, wp.array(fit.coefficient_matrix().astype(np.float32), dtype=float,
                                 device=ws.device),
                origin=ws.origin, spacing=ws.grid.spacing, point=tuple(point),
                axes=tuple(tuple(r) for r in frame), scale=scale)
            wp.copy(previous, ws.phi)
            # Damped fixed point: a fit made from intersections far from the truth can
            # overshoot until the rays miss; halve the step until no ray is lost. The rays
            # march by sign in half-cell steps, so the blends need no redistancing until the
            # last one is kept.
            accepted = False
            for beta in (1.0, 0.5, 0.25, 0.125):
                launch_blend(previous, fitted, ws.phi, beta=beta)
                ws.intersect()
                if ws.active.numpy().sum() >= ok.sum():
                    accepted = changed = True
                    break
            if not accepted:
                wp.copy(ws.phi, previous)
                break
        if changed:
            ws.redistancer.reinitialize(ws.phi)
            ws.version += 1


class ImplicitFit(Start):
    """The default start: any shape, fitted coarse to fine; false highlights rejected.

    A wrapper of :class:`warpspec.implicit.ImplicitStart` (docs/DESIGN.md section 7): the flow
    then uses only the rays the fit accepts.
    """

    def build(self, scene: Scene, ws: Workspace) -> StartOutcome:
        """Fit the implicit start into ``ws.phi``; ``keep`` holds the rays it accepts."""
        fit = ImplicitStart(scene, ws.grid, ws.device, initial_plane(scene, ws.grid),
                            progress=ws.progress)
        report = fit.run(ws.phi)
        if ws.progress is not None:
            ws.progress("the start redistanced, the narrow band built")
        if not (report.distance and ws.band is not None):
            # a quadric's first-order distance needs none near the surface, where the band is
            # read; the band's first reinitialisation makes the rest a distance
            ws.redistancer.reinitialize(ws.phi, cap=ws.far_cap)
        ws.version += 1
        start = ws.phi.numpy().copy()
        keep = np.flatnonzero(report.weights > 0.0) if scene.num_specularities \
            else np.zeros(0, dtype=int)
        return StartOutcome(bent=start, initial=start, report=report,
                            keep=keep if len(keep) < scene.num_specularities else None)


class GivenStart(Start):
    """A level set handed in, used as it is (a saved one is a signed distance already).

    Args:
        phi: The level set on the workspace's grid, ``float32``-representable and finite.
    """

    def __init__(self, phi: np.ndarray) -> None:
        self.phi = phi

    def __repr__(self) -> str:
        return f"GivenStart({'x'.join(map(str, self.phi.shape))})"

    def build(self, scene: Scene, ws: Workspace) -> StartOutcome:
        """Copy the level set into ``ws.phi``."""
        ws.phi.assign(wp.array(self.phi, dtype=float, device=ws.device))
        start = ws.phi.numpy().copy()
        return StartOutcome(bent=start, initial=start)


def check_level_set(phi: object, grid: Grid, field: str) -> np.ndarray:
    """``phi`` as a finite ``float32`` array of ``grid``'s shape.

    Raises:
        InputError: If it is not one, naming ``field``.
    """
    try:
        arr = np.asarray(phi, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{field}: expected a 3-D array of numbers, got "
                         f"{type(phi).__name__}") from None
    if arr.shape != grid.shape:
        raise InputError(f"{field}: has shape {arr.shape}, the grid {grid.shape}; pass the "
                         "grid it lives on as grid=")
    with np.errstate(over="ignore", invalid="ignore"):
        out = arr.astype(np.float32)
    if not np.all(np.isfinite(out)):
        raise InputError(f"{field}: holds non-finite values (or values beyond float32)")
    return out


def make_start(name: str, *, bulge: float, bulge_cap: float | None, fit_iterations: int,
               fit_degree: int) -> Start:
    """The start that ``Reconstructor(start=name, ...)`` names (options already checked)."""
    if name == "implicit":
        return ImplicitFit()
    if name == "height":
        return HeightStart(bulge=bulge, bulge_cap=bulge_cap, fit_iterations=fit_iterations,
                           fit_degree=fit_degree)
    return PaperStart(bulge=bulge, bulge_cap=bulge_cap)
