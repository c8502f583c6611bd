"""The orchestrating class: a workspace, a narrow-band tracker and a start, driven by launches.

``Reconstructor.step`` is nothing but launches; measures are reduced on the device and copied
back only when asked for. The driver never loops over voxels on the host.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable

import numpy as np
import warp as wp

from .._runtime import init, resolve_device
from ..errors import InputError, ReconstructionError
from ..geometry import crop_to_data_hull, crop_to_unwrapped_hull, keep_faces
from ..grid import Grid
from ..implicit import rejected_summary
from ..kernels.flow import launch_flow_step, launch_flow_step_band
from ..kernels.measures import MEASURE_SLOTS
from ..mesh import (
    faces_behind,
    is_open,
    supported_components,
    triangulate,
    triangulate_device,
)
from ..options import DEFAULTS, OPTIONS, default_iterations
from ..scene import Scene
from ..verdict import SUPPORT_RADIUS
from .starts import GivenStart, check_level_set, make_start
from .state import Result, check_covers, check_holds, load_state
from .tracker import BandTracker
from .workspace import Workspace

__all__ = ["MEASURE_KEYS", "Reconstructor", "reconstruct"]

MEASURE_KEYS = (
    "iteration",
    "normal_error",
    "point_error",
    "energy_normal",
    "energy_point",
    "energy_smooth",
    "energy_total",
    "active",
    "misses",
    "seconds",
)


class Reconstructor:
    """Reconstruct a surface from a scene by level-set gradient descent (paper eq. 21).

    Every option's default, unit and range is in :data:`warpspec.options.OPTIONS`. The solver
    works about ``origin``, the grid's centre (docs/DESIGN.md section 3): ``workspace`` holds
    positions measured from it, while ``scene``, ``grid`` and each :class:`Result` are in the
    scene's own coordinates.

    Args:
        scene: The scene (cameras, specularities, light, points).
        resolution: Cells along the longest side of the domain (``None``: the default, 64).
        alpha: Weight of the smoothness (surface area) term.
        bulge: Bending ``c`` of the paper's start (eq. 23): a positive value moves it toward
            the cameras by ``c`` times the distance to the nearest point.
        bulge_cap: Cap ``d_max`` on that distance, in voxel widths (``None``: no cap).
        device: Warp device or its name; ``None`` picks CUDA when available, else the CPU.
        reinit_every: Reset ``phi`` to a signed distance every this many iterations (0: never).
        point_weight: Rate ``w_P`` of the point term, in units of ``1/h^2`` (per unit time).
            The exact decay holds the zero set where it is but cannot move it across a point;
            a strong decay followed by reinitialisation snaps the zero set onto the node
            nearest each point, so keep it small.
        gaussian_width: Standard deviation ``eps`` of the point Gaussians, in voxel widths.
        normal_radius: Radius ``r_N`` of the balls that carry the constraint normals, in voxel
            widths.
        cfl: Time step as a fraction of the parabolic limit ``h^2 / (6 (1 + alpha))``.
        fit_iterations: Rounds of the height-field fit of ``start="height"``.
        fit_degree: Highest total degree of that height field's polynomial.
        start: The starting surface (:mod:`warpspec.solver.starts`): ``"implicit"`` (the
            default: any shape and topology, fitted coarse to fine to the points and normals,
            false highlights rejected), ``"height"`` (a height field over the paper's plane,
            refined ``fit_iterations`` times) or ``"paper"`` (the paper's plane, bent by
            ``bulge``).
        margin: Margin around the points when the scene gives no domain, as a fraction of
            the points' longest extent.
        narrow_band: Update only the nodes within this many voxel widths of the zero set
            (the band is rebuilt at every reinitialisation, so the zero set must move less
            than ``narrow_band - 2`` voxels between two); ``None`` updates every node, as
            does ``reinit_every=0``, which never rebuilds a band.
        graph: Capture each iteration's launches as a Warp graph and replay it; ``None``
            captures on CUDA, where it saves most launch overhead (on the CPU the band's size
            changes at every reinitialisation, and each change costs a new capture).
        grid: Use this grid instead of deriving one from the scene.
        phi0: Start from this level set instead of ``start``: a :class:`Result` (its level
            set and grid, e.g. ``Result.load(path)``) or an array on ``grid`` (or on the grid
            derived from the scene).
        resume: Start from a level set saved with :meth:`Result.save_phi` (its grid is used):
            ``phi0=Result.load(resume)`` without meshing it.
        progress: Called with a few words as each stage of the set-up begins (the quadric,
            each grid of the implicit start's ladder), for a progress display.

    Raises:
        InputError: If an option is out of range or of the wrong type, the grid would not fit
            on the device, ``phi0`` or ``resume`` is not a level set on a grid holding the
            scene, or a grid is given twice (``resume`` or a ``Result`` with ``grid`` or
            ``resolution``).
    """

    def __init__(
        self,
        scene: Scene,
        *,
        resolution: int | None = None,
        alpha: float = DEFAULTS["alpha"],
        bulge: float = DEFAULTS["bulge"],
        bulge_cap: float | None = DEFAULTS["bulge_cap"],
        device: str | None = None,
        reinit_every: int = DEFAULTS["reinit_every"],
        point_weight: float = DEFAULTS["point_weight"],
        gaussian_width: float = DEFAULTS["gaussian_width"],
        normal_radius: float = DEFAULTS["normal_radius"],
        cfl: float = DEFAULTS["cfl"],
        fit_iterations: int = DEFAULTS["fit_iterations"],
        fit_degree: int = DEFAULTS["fit_degree"],
        start: str = DEFAULTS["start"],
        margin: float = DEFAULTS["margin"],
        narrow_band: float | None = DEFAULTS["narrow_band"],
        graph: bool | None = None,
        grid: Grid | None = None,
        phi0: Result | np.ndarray | None = None,
        resume: str | os.PathLike | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise InputError(f"scene: expected a warpspec.Scene, got {type(scene).__name__}")
        if resume is not None and not isinstance(resume, str | os.PathLike):
            raise InputError(f"resume: expected the path of a saved level set, got "
                             f"{type(resume).__name__} {resume!r:.60}")
        if grid is not None and not isinstance(grid, Grid):
            raise InputError(f"grid: expected a warpspec.Grid, got {type(grid).__name__} "
                             f"{grid!r:.60}")
        given = {"resume": resume, "phi0": phi0}
        if resume is not None and phi0 is not None:
            raise InputError("resume: pass either resume or phi0, not both")
        own_grid = resume is not None or isinstance(phi0, Result)
        for name, value in (("grid", grid), ("resolution", resolution)):
            if own_grid and value is not None:
                which = "resume" if resume is not None else "phi0"
                raise InputError(f"{name}: {which} brings its own grid; pass no {name} with it")
        opts = {name: OPTIONS[name].check(value) for name, value in (
            ("alpha", alpha), ("bulge", bulge), ("bulge_cap", bulge_cap),
            ("reinit_every", reinit_every), ("point_weight", point_weight),
            ("gaussian_width", gaussian_width), ("normal_radius", normal_radius),
            ("cfl", cfl), ("fit_iterations", fit_iterations), ("fit_degree", fit_degree),
            ("start", start), ("margin", margin), ("narrow_band", narrow_band))}
        if opts["start"] == "implicit" and (opts["bulge"] != 0.0 or bulge_cap is not None):
            raise InputError("bulge: bends the paper's plane only; the implicit start needs no "
                             "bulge (pass start='paper' or 'height' to use one)")
        self.scene = scene
        self.alpha = opts["alpha"]
        self.point_weight = opts["point_weight"]
        self.reinit_every = opts["reinit_every"]
        self.cfl = opts["cfl"]
        self.start = opts["start"]

        if resume is not None:
            phi0, grid = load_state(resume)
            check_covers(scene, grid, f"resume: {os.fspath(resume)!r}")
        elif isinstance(phi0, Result):
            phi0, grid = phi0.phi, phi0.grid
            check_covers(scene, grid, "phi0")
        elif grid is None:
            resolution = OPTIONS["resolution"].check(
                DEFAULTS["resolution"] if resolution is None else resolution)
            lo, hi = scene.bounds(margin=opts["margin"])
            grid = Grid.from_bounds(lo, hi, resolution=resolution)
            check_holds(scene, grid, "domain")
        else:
            check_holds(scene, grid, "grid")
        if phi0 is not None:
            strategy = GivenStart(check_level_set(phi0, grid, next(
                k for k, v in given.items() if v is not None)))
        else:
            strategy = make_start(self.start, bulge=opts["bulge"], bulge_cap=opts["bulge_cap"],
                                  fit_iterations=opts["fit_iterations"],
                                  fit_degree=opts["fit_degree"])
        self.grid = grid
        # the solver works about the grid's centre; results are moved back (Scene.translated)
        self.origin = grid.origin + 0.5 * grid.spacing * (np.asarray(grid.shape) - 1)
        self._scene = scene.translated(self.origin)
        self._grid = Grid(origin=grid.origin - self.origin, spacing=grid.spacing,
                          shape=grid.shape)
        self.device = resolve_device(device)
        self.workspace = Workspace(self._scene, self._grid, self.device,
                                   gaussian_width=opts["gaussian_width"],
                                   normal_radius=opts["normal_radius"],
                                   band=opts["narrow_band"] is not None and self.reinit_every > 0)
        self._tracker = BandTracker(self.workspace, width=opts["narrow_band"])
        self.workspace.far_cap = self._tracker.far_cap
        self.workspace.progress = progress

        h = grid.spacing
        self.dt = self.cfl * h * h / (6.0 * (1.0 + self.alpha))
        self.w_point = self.point_weight / (h * h)
        eps = opts["gaussian_width"] * h
        self.point_energy_weight = self.w_point * (2.0 * math.pi) ** 1.5 * eps**3
        self.iteration = 0
        self.history: list[dict] = []
        self._graphs: dict = {}
        self._clock = 0.0
        self.graph = self.device.is_cuda if graph is None else bool(graph)

        outcome = strategy.build(self._scene, self.workspace)
        self.start_surface = strategy
        self.fit_report = outcome.report
        self.bent_phi, self.initial_phi = outcome.bent, outcome.initial
        if outcome.keep is not None:
            self.workspace.use_rays(outcome.keep)
        self._tracker.keep_good(0)
        self._tracker.rebuild()
        self.workspace.intersect()

    def __repr__(self) -> str:
        return (f"Reconstructor({self.grid!r}, start={self.start!r}, iteration "
                f"{self.iteration}, {self.device.alias})")

    @property
    def phi(self) -> np.ndarray:
        """A host copy of the current level set: changing it changes nothing in the solver.

        The live device array is ``workspace.phi``; each step writes its twin and swaps them.
        """
        return self.workspace.phi.numpy().copy()

    # -- iteration ------------------------------------------------------------------------

    def _reinitialize(self) -> None:
        """Check ``phi``, redistance it, rebuild the band and keep it as the last good state.

        Raises:
            ReconstructionError: If ``phi`` holds a non-finite value; the last good state is
                restored first.
        """
        self._check_finite()
        self._tracker.reinitialize(self.iteration)

    def _check_finite(self, sums: np.ndarray | None = None) -> None:
        sums = self._tracker.sums() if sums is None else sums
        bad = self._tracker.nonfinite(sums)
        if bad == 0:
            return
        failed = self.iteration
        self.iteration = self._tracker.roll_back()
        self.history = [m for m in self.history if m["iteration"] <= self.iteration]
        raise ReconstructionError(
            f"iteration {failed}: phi has {bad} non-finite values; the solver is back at the "
            f"state of iteration {self.iteration}; lower cfl or point_weight"
        )

    def step(self) -> None:
        """Advance one iteration: intersect the rays, take one flow step, reinitialise on time."""
        self._step()

    def _step(self, *, normal: bool = True, smooth: bool = True, points: bool = True,
              intersect: bool = True) -> None:
        """One iteration, with terms switched off (for tests).

        ``intersect=False`` keeps the last intersections: the flow then descends the normal
        energy of fixed hits.
        """
        ws = self.workspace
        if normal and smooth and points and intersect and self.graph:
            key = (id(ws.phi), self._tracker.size)
            graph = self._graphs.get(key)
            if graph is None:
                if self.device.is_cpu:  # the band's size changed: older graphs are stale
                    self._graphs.clear()
                with wp.ScopedCapture(device=self.device) as capture:
                    self._launch_step(True, True, True, True)
                graph = self._graphs[key] = capture.graph
            wp.capture_launch(graph)
        else:
            if intersect:
                ws.current_hits()
            self._launch_step(normal, smooth, points, False)
        ws.swap()
        self.iteration += 1
        if self.reinit_every and self.iteration % self.reinit_every == 0:
            self._reinitialize()

    def _launch_step(self, normal: bool, smooth: bool, points: bool, intersect: bool) -> None:
        """The launches of one iteration, from ``phi`` into its ping-pong twin."""
        ws = self.workspace
        if intersect:
            ws.intersect()
        weights = {
            "spacing": self.grid.spacing,
            "dt": self.dt,
            "normal_weight": 1.0 if normal else 0.0,
            "alpha": self.alpha if smooth else 0.0,
            "point_weight": self.w_point if points else 0.0,
        }
        if ws.band is None:
            launch_flow_step(ws.phi, ws.owner, ws.normals, ws.gauss, ws.tmp, **weights)
        else:
            launch_flow_step_band(ws.phi, ws.owner, ws.normals, ws.gauss, ws.band,
                                  ws.band_count, ws.tmp, size=self._tracker.size, **weights)

    def reinitialize(self) -> None:
        """Reset ``phi`` to the signed distance to its zero set now."""
        self._reinitialize()

    def measures(self, *, intersect: bool = True) -> dict:
        """Reduce the measures of the current state on the device and return them.

        Args:
            intersect: Intersect the rays with the current ``phi`` first (``False`` measures
                against the intersections of the last step).

        Raises:
            ReconstructionError: If ``phi`` holds a non-finite value.
        """
        if intersect:
            self.workspace.current_hits()
        s = self._tracker.sums()
        self._check_finite(s)
        active = int(s[MEASURE_SLOTS["active"]])
        npts = max(self._scene.num_points, 1)
        e_n = float(s[MEASURE_SLOTS["energy_normal"]])
        # E_P = sum |phi(y)|, weighted as the flow weighs it: w_P times the Gaussian's volume.
        e_p = self.point_energy_weight * float(s[MEASURE_SLOTS["point_abs_sum"]])
        e_s = float(s[MEASURE_SLOTS["energy_smooth"]])
        return {
            "iteration": self.iteration,
            "normal_error": float(s[MEASURE_SLOTS["normal_error_sum"]] / active) if active
            else float("nan"),
            "point_error": float(s[MEASURE_SLOTS["point_abs_sum"]] / npts / self.grid.spacing)
            if self._scene.num_points else float("nan"),
            "energy_normal": e_n,
            "energy_point": e_p,
            "energy_smooth": e_s,
            "energy_total": e_n + e_p + self.alpha * e_s,
            "active": active,
            "misses": int(s[MEASURE_SLOTS["misses"]]),
            "seconds": self._clock,
        }

    def run(
        self,
        iterations: int,
        *,
        measure_every: int = DEFAULTS["measure_every"],
        callback: Callable[[dict], None] | None = None,
    ) -> list[dict]:
        """Advance ``iterations`` steps, recording measures every ``measure_every`` of them.

        The measures of the start (when ``history`` is empty) and of the last iteration are
        always recorded.

        Args:
            iterations: Number of iterations.
            measure_every: Record the measures every this many iterations (0, the default:
                only the last). Each record is a reduction over the narrow band and a
                synchronisation with the device: about 15% of an iteration at 64^3 on the
                CPU.
            callback: Called with each recorded measure dict (progress display).

        Returns:
            The measures recorded during this call (also appended to ``history``).
        """
        iterations = OPTIONS["iterations"].check(iterations)
        measure_every = OPTIONS["measure_every"].check(measure_every)
        recorded = []
        if not self.history:
            self._record(recorded, callback)
        for n in range(1, iterations + 1):
            start = time.perf_counter()
            self.step()
            self._clock += time.perf_counter() - start
            if (measure_every and n % measure_every == 0) or n == iterations:
                self._record(recorded, callback)
        return recorded

    def _record(self, recorded: list, callback: Callable[[dict], None] | None) -> None:
        m = self.measures()
        self.history.append(m)
        recorded.append(m)
        if callback is not None:
            callback(m)

    def _hit_normals(self, hits: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The finite hits, the scene's normals there, which the fit kept, their cameras.

        The last is the centres of the cameras whose rays met the surface at the hits.
        """
        ok = np.all(np.isfinite(hits), axis=1)
        kept = np.ones(len(hits), dtype=bool)
        if self.fit_report is not None:
            kept[self.fit_report.rejected] = False
        origins, dirs = self._scene.rays()
        normals = self._scene.normals(np.where(ok[:, None], hits, origins + dirs))[ok]
        return hits[ok], normals, kept[ok], origins[ok]

    def _wraps_around(self, normals: np.ndarray, hits: np.ndarray) -> bool:
        """Whether the kept normals at the hits turn by more than :data:`TURN_DEG`.

        Then the data bends round (a cylinder patch seen from a ring of cameras) and, unless
        it is seen all around, the fit's extrapolation carries on round, behind the data: the
        crop is needed. A patch leaves an arc of the normals empty where its data stops,
        wider than :data:`OPEN_ARC_DEG`, and the cameras that saw highlights leave that side
        unwatched (their widest empty arc round the hits is :data:`OPEN_ARC_RATIO` times any
        other and wider than OPEN_ARC_DEG). Seen all around, the views, however few, space
        their arcs alike, and an empty arc of the normals is highlights lost, not the data's
        edge: a bottle under lamps with a quarter false, seed 200, whose rejected highlights
        left 95 degrees of the normals empty (its cameras' arcs within 1.14 times of each
        other), was cut open along it, 1.23 h from the truth instead of 0.03. Turning less,
        the open surface is kept whole: its rims lie beyond the data by the curvature between
        far-apart constraints, and a crop would cut into them (the wine bottle's label).
        """
        if _gentle(normals):
            return False
        # Around what axis, and how far: the empty arcs in the normals' principal plane.
        _, _, vt = np.linalg.svd(normals, full_matrices=False)
        widest, _ = _widest_arcs(normals @ vt[0], normals @ vt[1])
        if widest <= OPEN_ARC_DEG:
            return False
        # Cameras are where the user looked from; a false highlight does not move them.
        seen_from = self._scene.rays()[0] - hits.mean(axis=0)
        widest, next_widest = _widest_arcs(seen_from @ vt[0], seen_from @ vt[1])
        return bool(widest > OPEN_ARC_DEG and widest >= OPEN_ARC_RATIO * next_widest)

    def _crop_round(self, vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray,
                    hits: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Crop a surface bending round to the data.

        Round the axis of the kept rays' normals (a false highlight's is not the surface's),
        or, where they fix none, in the hulls of the anchors.
        """
        cropped = crop_to_unwrapped_hull(vertices, faces, anchors, hits, normals,
                                         margin=UNWRAPPED_MARGIN * self.grid.spacing)
        if cropped is not None:
            return cropped
        # a fixed share of the domain, so that the crop does not depend on the resolution
        margin = CROP_MARGIN * float(np.max(self.grid.upper - self.grid.origin))
        margin = max(margin, SUPPORT_RADIUS * self.grid.spacing)
        return crop_to_data_hull(vertices, faces, anchors, margin=margin)

    def _seen_from_one_side(self) -> bool:
        """Whether the start found the cameras in a half-space (its first guess a plane)."""
        return self.fit_report is not None and self.fit_report.guess == "plane"

    def _crop_behind(self, vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray,
                     hits: np.ndarray, normals: np.ndarray, seen_from: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Drop the surface behind a gentle patch seen from one side.

        The fit's extrapolation may close behind the data (the octant's sphere, in a domain
        that holds it); no constraint speaks for that side. The faces turned away from the
        data's mean normal or from every camera, in pieces that come no nearer the data than
        :data:`BEHIND_VOXELS`, are dropped (:func:`warpspec.mesh.faces_behind`). The mesh's
        sense is the one the kept hits (``hits``, with the scene's ``normals`` there, seen
        from the camera centres ``seen_from``) turn to their own cameras.
        """
        if len(hits) == 0:
            return vertices, faces
        behind = faces_behind(vertices, faces, anchors, front=normals.mean(axis=0),
                              viewpoints=self._scene.camera_centres(), seen=(hits, seen_from),
                              radius=BEHIND_VOXELS * self.grid.spacing)
        if not behind.any() or behind.all():
            return vertices, faces
        return self._pieces(*keep_faces(vertices, faces, ~behind), anchors)

    def _pieces(self, vertices: np.ndarray, faces: np.ndarray, anchors: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """The mesh without its pieces far from the data, and without specks.

        See :func:`warpspec.mesh.supported_components`.
        """
        return supported_components(vertices, faces, anchors,
                                    radius=SUPPORT_RADIUS * self.grid.spacing,
                                    min_extent=SPECK_VOXELS * self.grid.spacing)

    @property
    def default_iterations(self) -> int:
        """Iterations of the flow the automatic schedule gives this grid."""
        return default_iterations(max(self.grid.shape) - 1)

    def result(self, *, crop: bool = True) -> Result:
        """The current surface as a :class:`Result` (mesh, level set, grid, history).

        Args:
            crop: Crop an open surface that bends round (:meth:`_wraps_around`) to where the
                data reaches: the faces inside the convex hull of the rays' hits and the
                points in the surface's own coordinates round its axis (arc length and
                height), grown by :data:`UNWRAPPED_MARGIN` voxels
                (:func:`warpspec.geometry.crop_to_unwrapped_hull`); where the normals fix no
                axis, inside their 3-D and 2-D hulls grown by :data:`CROP_MARGIN` of the
                domain (:func:`warpspec.geometry.crop_to_data_hull`). Beyond them the surface
                is the fit's extrapolation, which no constraint speaks for. A gentler surface
                seen from one side loses what lies behind the data (:meth:`_crop_behind`),
                even when it is closed; any other closed surface is never cropped. ``False``
                keeps the whole zero set.

        Raises:
            ReconstructionError: If the zero set has left the domain (no surface to mesh).
        """
        phi = self.phi
        ws = self.workspace
        hits = ws.scene_hits(self._scene.num_specularities)
        if ws.band is not None and self._tracker.width >= 2.0:
            # on the device, over the band's cells: no full grid through marching cubes
            vertices, faces = triangulate_device(ws.phi, self._grid, band=ws.band,
                                                 count=ws.band_count)
        else:
            vertices, faces = triangulate(phi, self._grid)
        anchors = np.vstack([hits[np.all(np.isfinite(hits), axis=1)],
                             self._scene.points.reshape(-1, 3)])
        vertices, faces = self._pieces(vertices, faces, anchors)
        if crop and len(faces):
            hit_points, normals, kept, seen_from = self._hit_normals(hits)
            if self._seen_from_one_side() and _gentle(normals[kept]):
                vertices, faces = self._crop_behind(vertices, faces, anchors, hit_points[kept],
                                                    normals[kept], seen_from[kept])
            elif is_open(faces) and self._wraps_around(normals[kept], hit_points[kept]):
                vertices, faces = self._crop_round(vertices, faces, anchors, hit_points[kept],
                                                   normals[kept])
        rejected = ([] if self.fit_report is None
                    else rejected_summary(self.fit_report, self._scene))
        local = Result(vertices=vertices, faces=faces, phi=phi, grid=self._grid,
                       history=list(self.history), hits=hits, rejected=rejected)
        local.assess(self._scene)
        return dataclasses.replace(local, vertices=vertices + self.origin,
                                   hits=hits + self.origin, grid=self.grid)


def _widest_arcs(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The widest and the next widest empty arc (degrees) between the directions ``(x, y)``."""
    angles = np.sort(np.arctan2(y, x))
    gaps = np.sort(np.diff(np.concatenate([angles, angles[:1] + 2.0 * np.pi])))
    return float(np.degrees(gaps[-1])), float(np.degrees(gaps[-2]) if len(gaps) > 1 else 0.0)


def _gentle(normals: np.ndarray) -> bool:
    """Whether no two of the unit ``normals`` are more than :data:`TURN_DEG` apart."""
    if len(normals) < 2:
        return True
    cos_turn = np.cos(np.radians(TURN_DEG))
    step = max(1, PAIR_CHUNK // len(normals))  # bounded memory: normals x normals
    return all(np.min(normals[k:k + step] @ normals.T) >= cos_turn
               for k in range(0, len(normals), step))


TURN_DEG = 120.0
"""The widest angle between two normals of an open surface kept whole. Turning further, the
fit's extrapolation past the data bends on round, behind it: a cylinder patch of 185 degrees
whose highlights' normals span 166 kept the back of the cylinder, 3 voxels from the truth on
average and 25 at worst. The paper's scenes and the free-form and point-lit patches span
15-85 degrees; their rims stay."""
PAIR_CHUNK = 1 << 22
"""Normal pairs compared at once by :meth:`Reconstructor._wraps_around` (32 MiB of float64)."""
OPEN_ARC_DEG = 45.0
"""An empty arc of the normals wider than this marks where a patch's data stops when the
cameras leave that side unwatched (see OPEN_ARC_RATIO): a patch wrapping 310-330 degrees (36
highlights inset by 5% of the span from its edges, a quarter of them false) leaves one of
63-81 degrees and was closed into a tube 0.7-1.6 voxels from the truth on average; cropped,
0.03-0.06. Bottles seen from rings of 14-20 cameras leave arcs of 21-26 degrees by flash and up
to 95 under lamps with a quarter false (seeds 0-39 and 200): those cameras stand all round.
Patches wrapping 200-330 degrees (seeds 0-5, clean and a quarter false) leave their cameras
an arc of 60 degrees or more, 2.0 times any other or more."""
OPEN_ARC_RATIO = 1.5
"""Cameras leave one side unwatched when their widest empty arc round the hits is this many
times the next (and wider than OPEN_ARC_DEG): the views of a tube seen all around, however
few, space their arcs alike (the bottles' rings of cameras, seeds 0-5: at most 1.13 times);
those of the patch wrapping 330 degrees leave 2.0-2.5 times (seeds 0-2)."""
BEHIND_VOXELS = 3.0
"""A piece of the surface turned away from the data (from the kept rays' mean normal, or from
every camera) is dropped from a gentle patch seen from one side when it comes no nearer the
data than this many voxels (:meth:`Reconstructor._crop_behind`)."""
SPECK_VOXELS = 2.0
"""Pieces of the mesh whose bounding box is less than this many voxels across (its
diagonal) are specks of the level set, not surfaces the grid resolves: they are dropped."""
UNWRAPPED_MARGIN = 2.0
"""Margin, in voxel widths, of the crop of an open surface bending round, in its own
coordinates round the axis (:func:`warpspec.geometry.crop_to_unwrapped_hull`). On the wrap
scene (seeds 0, 1 and 3; clean, 10% and 25% false) the truth within the data's hull is 0.013 h
from the mesh at 2 and at 3 voxels and 0.020-0.023 h at 1; the mesh, which runs on past the
data's edge, is 0.014-0.015 h from the truth at 1, 0.017-0.032 h at 2 and 0.035-0.093 h at 3."""
CROP_MARGIN = 3.0 / 64.0
"""Margin of the crop of an open surface whose normals fix no axis, in the anchors' 3-D and
2-D hulls, as a share of the domain's longest side: three voxels at resolution 64 (the hulls'
facets are chords, which the margin must reach past to keep the rims)."""


def reconstruct(scene: Scene | str | os.PathLike, *,
                iterations: int | None = DEFAULTS["iterations"], **options) -> Result:
    """Reconstruct a surface in one call.

    Args:
        scene: A :class:`Scene` or the path of a scene file.
        iterations: Number of iterations of the flow; ``None`` (the default) chooses it from
            the resolution (:func:`warpspec.options.default_iterations`: 300 up to 64 cells,
            fewer on finer grids, whose start is already solved coarse to fine).
        **options: Keyword options of :class:`Reconstructor`.

    Returns:
        The :class:`Result`, with its :attr:`~Result.verdict` and :attr:`~Result.support`.

    Raises:
        InputError: For a bad option or file (``SceneError`` for a field of the scene).
        ReconstructionError: If the run fails (a non-finite level set, no surface).
    """
    init()
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    solver = Reconstructor(scene, **options)
    solver.run(solver.default_iterations if iterations is None else iterations)
    return solver.result()
