"""The reconstruction driver: owns the device arrays and advances the level set.

The driver never loops over voxels on the host: every pass over the grid is a Warp kernel.
``Reconstructor.step`` is nothing but launches; measures are reduced on the device and copied
back only when asked for.
"""

from __future__ import annotations

import math
import os
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from ._atomic import atomic_write, check_size
from ._runtime import init, resolve_device
from .errors import InputError, ReconstructionError, SceneError
from .grid import MAX_NODES, Grid
from .implicit import ImplicitStart, rejected_summary
from .initial import fit_height_field, plane_frame
from .kernels.constraints import (
    launch_bend,
    launch_blend,
    launch_claim_normals,
    launch_gaussian,
    launch_height_field,
    launch_plane,
)
from .kernels.differences import (
    launch_build_band,
    launch_flow_step,
    launch_flow_step_band,
    launch_init_flow_step,
)
from .kernels.rays import MEASURE_SLOTS, NUM_SLOTS, launch_intersect, launch_measures
from .kernels.redistance import Redistancer
from .mesh import (
    crop_to_data_hull,
    data_crop_limit,
    is_open,
    supported_components,
    triangulate,
    triangulate_device,
    write_ply,
)
from .options import STARTS, default_iterations
from .scene import Scene
from .verdict import SUPPORT_RADIUS, Verdict, assess

if TYPE_CHECKING:
    import trimesh

__all__ = ["Reconstructor", "Result", "reconstruct"]

REINIT_BAND = "gradient"
FULL_REINIT_EVERY = 5
FAR_CAP_MARGIN = 4.0
"""Voxels beyond the narrow band that a full redistance still computes exactly."""

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


@dataclass(repr=False)
class Result:
    """What a reconstruction returns.

    Attributes:
        vertices: Vertices of the zero set's triangulation, world coordinates, ``(n, 3)``.
        faces: Its triangles, ``(m, 3)`` vertex indices, wound outward (toward ``phi > 0``
            and the cameras).
        phi: The level set on the grid, ``float32``, indexed ``[i, j, k]``.
        grid: The grid ``phi`` lives on.
        history: Per-iteration measures, one dict per recorded iteration (keys:
            ``iteration``, ``normal_error`` (mean ``1 - N.n`` over active rays),
            ``point_error`` (mean ``|phi(y)|`` over the points, in voxel widths),
            ``energy_normal``, ``energy_point``, ``energy_smooth``, ``energy_total``,
            ``active``, ``misses``, ``seconds``).
        hits: Ray intersections of the last iteration, ``(M, 3)``; NaN for missed rays.
        support: Per vertex, the distance to the nearest constraint (a ray's hit or a point)
            in voxel widths, ``(n,)``; written to PLY as the vertex property ``support``.
        verdict: Whether the data supports the result (:class:`warpspec.verdict.Verdict`).
        rejected: The highlights the start rejected as inconsistent with the others (a false
            detection, another light's reflection), one dict each: ``index`` (in the scene's
            specularities), ``camera``, ``pixel`` and ``residual_deg`` (the angle between its
            normal and the fitted surface's); they take no part in the flow.
    """

    vertices: np.ndarray
    faces: np.ndarray
    phi: np.ndarray
    grid: Grid
    history: list[dict] = field(default_factory=list)
    hits: np.ndarray | None = None
    support: np.ndarray | None = None
    verdict: Verdict | None = None
    rejected: list[dict] = field(default_factory=list)
    _mesh: object = field(default=None, init=False, repr=False, compare=False)

    def __repr__(self) -> str:
        verdict = "not assessed" if self.verdict is None else (
            "supported" if self.verdict.supported else "NOT supported")
        return (f"Result({len(self.vertices)} vertices, {len(self.faces)} faces, "
                f"{self.grid!r}, {len(self.history)} measures, {verdict})")

    @property
    def mesh(self) -> trimesh.Trimesh:
        """The triangulation as a ``trimesh.Trimesh`` (made, and trimesh imported, on first use)."""
        if self._mesh is None:
            import trimesh

            self._mesh = trimesh.Trimesh(vertices=self.vertices, faces=self.faces,
                                         process=False)
        return self._mesh

    def write_mesh(self, path: str | os.PathLike) -> None:
        """Write the triangulation in the format that ``path``'s extension names, atomically.

        ``.ply`` is written directly (binary, as trimesh writes it, with the vertex property
        ``support`` when known); other formats go through ``trimesh.Trimesh.export``.
        """
        path = Path(path)
        if path.suffix.lower() == ".ply":
            extra = None if self.support is None else {"support": self.support}
            atomic_write(path, lambda tmp: write_ply(tmp, self.vertices, self.faces,
                                                     vertex_properties=extra))
        else:
            atomic_write(path, lambda tmp: self.mesh.export(tmp, file_type=path.suffix[1:]
                                                            .lower()))

    def constraint_anchors(self, scene: Scene) -> np.ndarray:
        """The ray intersections that hit and the point constraints, stacked ``(n, 3)``."""
        hits = np.empty((0, 3)) if self.hits is None else self.hits
        return np.vstack([hits[np.all(np.isfinite(hits), axis=1)], scene.points.reshape(-1, 3)])

    def assess(self, scene: Scene) -> Verdict:
        """Compute (again) :attr:`verdict` and :attr:`support` against ``scene``."""
        normals = None
        if self.hits is not None and scene.num_specularities:
            hits = np.asarray(self.hits, dtype=np.float64)
            ok = np.all(np.isfinite(hits), axis=1)
            origins, dirs = scene.rays()
            normals = scene.normals(np.where(ok[:, None], hits, origins + dirs))
            normals[~ok] = np.nan
        self.verdict, self.support = assess(
            phi=self.phi, grid=self.grid, vertices=self.vertices, hits=self.hits,
            demanded_normals=normals, points=scene.points)
        return self.verdict

    def save_phi(self, path: str | os.PathLike) -> None:
        """Save the level set and its grid to an ``.npz`` file (``Reconstructor(resume=...)``)."""
        save_state(path, self.phi, self.grid)


MAX_STATE_BYTES = 4 * 2**30
"""Largest level-set file :func:`load_state` opens (a 1024^3 float32 level set is 4 GiB)."""


def save_state(path: str | os.PathLike, phi: np.ndarray, grid: Grid) -> None:
    """Write ``phi`` and its grid to ``path`` (NPZ), through a unique temporary file and a rename.

    Raises:
        OSError: If it cannot be written; a file already at ``path`` is left as it was.
    """
    atomic_write(path, lambda tmp: write_state(tmp, phi, grid))


def write_state(path: str | os.PathLike, phi: np.ndarray, grid: Grid) -> None:
    """Write ``phi`` and its grid to ``path`` as NPZ, directly (:func:`save_state` renames)."""
    with open(path, "wb") as f:
        np.savez_compressed(f, phi=np.asarray(phi, dtype=np.float32), origin=grid.origin,
                            spacing=grid.spacing, shape=np.asarray(grid.shape))


def _npz_header(archive: zipfile.ZipFile, key: str) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of one array of an NPZ, read from its header without expanding it."""
    with archive.open(key + ".npy") as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(f)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(f)
    return tuple(shape), np.dtype(dtype)


def _free_host_memory() -> int | None:
    """Bytes of physical memory free now, or ``None`` where the system does not say."""
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def load_state(path: str | os.PathLike, *, max_nodes: int | None = None) -> tuple[np.ndarray, Grid]:
    """Read a level set saved by :func:`save_state`.

    The file's size, the arrays' declared shapes and the grid are checked before anything is
    expanded: a small compressed file cannot claim gigabytes.

    Args:
        path: The ``.npz`` file.
        max_nodes: Refuse a level set of more nodes (default: :data:`warpspec.grid.MAX_NODES`).

    Raises:
        InputError: If the file is missing, too large, unreadable or not a saved level set.
    """
    if not isinstance(path, str | os.PathLike):
        raise InputError(f"resume: expected the path of a saved level set, got "
                         f"{type(path).__name__} {path!r:.60}")
    where = repr(os.fspath(path))
    if not os.path.exists(path):
        raise InputError(f"resume: no such file {where}")
    if os.path.isdir(path):
        raise InputError(f"resume: {where} is a folder, expected a .npz file")
    check_size(path, MAX_STATE_BYTES, "resume")
    limit = MAX_NODES if max_nodes is None else int(max_nodes)
    not_state = f"resume: {where} is not a saved warpspec level set"
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            for key in ("phi", "origin", "spacing", "shape"):
                if key + ".npy" not in names:
                    raise InputError(f"{not_state} (no array {key!r}); write one with "
                                     "--save-phi")
            headers = {key: _npz_header(archive, key) for key in ("phi", "shape", "origin",
                                                                  "spacing")}
            for key, want in (("shape", (3,)), ("origin", (3,)), ("spacing", ())):
                if headers[key][0] != want or headers[key][1].kind not in "iuf":
                    raise InputError(f"{not_state} ({key!r} has shape {headers[key][0]})")
            shape, dtype = headers["phi"]
            count = math.prod(shape) if shape else 1
            if len(shape) != 3 or dtype.kind != "f" or count > limit:
                raise InputError(f"{not_state} or is too large: 'phi' is declared {dtype} of "
                                 f"shape {shape} (at most {limit:.3g} float values)")
            need = count * (dtype.itemsize + 4)  # the array as stored, then as float32
            free = _free_host_memory()
            if free is not None and need > free:
                raise InputError(f"resume: {where} holds a level set of shape {shape} that "
                                 f"needs {need / 2**30:.1f} GiB to read, but only "
                                 f"{free / 2**30:.1f} GiB of memory is free")
            member = archive.getinfo("phi.npy")
            if member.file_size > count * dtype.itemsize + 4096:
                raise InputError(f"{not_state}: 'phi.npy' expands to {member.file_size} bytes, "
                                 f"more than its shape {shape} holds")
            small = {k: np.load(archive.open(k + ".npy")) for k in ("shape", "origin",
                                                                     "spacing")}
            grid = Grid(origin=small["origin"], spacing=float(small["spacing"]),
                        shape=tuple(int(s) for s in small["shape"]))
            if tuple(shape) != grid.shape:
                raise InputError(f"resume: {where} holds a level set of shape {shape} on a "
                                 f"grid of shape {grid.shape}")
            with np.errstate(all="ignore"):
                phi = np.array(np.load(archive.open("phi.npy")), dtype=np.float32)
    except InputError:
        raise
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile,
            zipfile.LargeZipFile) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(f"{not_state} ({reason}); write one with --save-phi") from None
    if not np.all(np.isfinite(phi)):
        raise InputError(f"resume: {where} holds non-finite values (or values beyond float32)")
    return phi, grid


def _check_covers(scene: Scene, grid: Grid, path: str | os.PathLike) -> None:
    """Refuse a resumed level set whose grid does not hold the scene's constraints.

    Raises:
        InputError: If a point lies outside the grid, or no specular ray enters it.
    """
    from .scene import rays_meet_box

    lo, hi, h = grid.origin, grid.upper, grid.spacing
    box = f"min={np.round(lo, 6).tolist()} max={np.round(hi, 6).tolist()}"
    outside = int(np.sum(np.any((scene.points < lo - h) | (scene.points > hi + h), axis=1)))
    if outside:
        raise InputError(f"resume: {os.fspath(path)!r} was saved on a grid ({box}) that leaves "
                         f"{outside} of the scene's {scene.num_points} points outside; resume "
                         "only with the scene it was saved from")
    if scene.num_specularities:
        origins, dirs = scene.rays()
        if not rays_meet_box(origins, dirs, lo, hi).any():
            raise InputError(f"resume: {os.fspath(path)!r} was saved on a grid ({box}) that no "
                             "specular ray of the scene enters; resume only with the scene it "
                             "was saved from")


MAX_ALPHA = 1e4
"""Largest smoothness weight: the time step shrinks as ``1 / (1 + alpha)``, so beyond this the
flow does not move in any number of iterations, and ``alpha / h`` nears float32's range."""
MAX_BULGE = 100.0
"""Largest ``|bulge|``: the start moves by ``bulge`` times the distance to the nearest point,
so beyond this it leaves any domain (the paper uses 0.3 and 0.5)."""


def _positive_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"{name}: must be a positive integer, got {value!r}")
    return int(value)


def _non_negative_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise InputError(f"{name}: must be a non-negative integer, got {value!r}")
    return int(value)


def _real(name: str, value: object, *, low: float | None = None, strict: bool = False,
          high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"{name}: must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{name}: must be finite, got {value!r}")
    if low is not None and (v <= low if strict else v < low):
        bound = "greater than" if strict else "at least"
        raise InputError(f"{name}: must be {bound} {low}, got {value!r}")
    if high is not None and v > high:
        raise InputError(f"{name}: must be at most {high}, got {value!r}")
    return v


def initial_plane(scene: Scene, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """The plane the paper starts from: a point on it and its unit normal toward the cameras.

    Least squares through the points when there are three or more that are not collinear;
    otherwise through their centroid (the domain's centre without points) with the mean of
    the constraint normals as its normal.
    """
    points = scene.points
    centres = scene.camera_centres()
    if len(points):
        centroid = points.mean(axis=0)
    else:
        centroid = grid.origin + 0.5 * (grid.upper - grid.origin)
    normal = None
    if len(points) >= 3:
        _, s, vt = np.linalg.svd(points - centroid)
        if s[1] > 1e-6 * max(s[0], 1e-300):
            normal = vt[2]
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


class Reconstructor:
    """Reconstruct a surface from a scene by level-set gradient descent (paper eq. 21).

    Args:
        scene: The scene (cameras, specularities, light, points).
        resolution: Cells along the longest side of the domain.
        alpha: Weight of the smoothness (surface area) term.
        bulge: Bending ``c`` of the initial surface (paper eq. 23): a positive value moves it
            toward the cameras by ``c`` times the distance to the nearest point.
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
        init_iterations: Steps of the Zhao-Osher-Fedkiw flow that pull the initial plane
            toward the points before bending (0: the plane as it is).
        fit_iterations: Rounds of the normal-informed start: a height field over the initial
            plane is fitted to the points and to the normals where the rays meet the current
            start (the bent plane first), then re-intersected. 0 gives the paper's start
            (plane and bend) unchanged. The flow's normal term is local to the constraints,
            so the shape between them comes from the start.
        fit_degree: Highest total degree of that height field's polynomial.
        start: The starting surface: ``"implicit"`` (the default: any shape and topology,
            fitted coarse to fine to the points and normals, false highlights rejected),
            ``"height"`` (a height field over the paper's plane, refined ``fit_iterations``
            times) or ``"paper"`` (the paper's plane, bent by ``bulge``).
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
        resume: Start from a level set saved with :meth:`Result.save_phi` (its grid is used).

    Raises:
        InputError: If an option is out of range or of the wrong type, the grid would not fit
            on the device, or ``resume`` is not a level set saved on a grid holding the scene.
    """

    def __init__(
        self,
        scene: Scene,
        *,
        resolution: int = 64,
        alpha: float = 0.01,
        bulge: float = 0.0,
        bulge_cap: float | None = None,
        device: str | None = None,
        reinit_every: int = 10,
        point_weight: float = 0.02,
        gaussian_width: float = 1.0,
        normal_radius: float = 1.0,
        cfl: float = 0.9,
        init_iterations: int = 0,
        fit_iterations: int = 5,
        fit_degree: int = 4,
        start: str = STARTS[0],
        margin: float = 0.2,
        narrow_band: float | None = 4.0,
        graph: bool | None = None,
        grid: Grid | None = None,
        resume: str | os.PathLike | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise InputError(f"scene: expected a warpspec.Scene, got {type(scene).__name__}")
        if resume is not None and not isinstance(resume, str | os.PathLike):
            raise InputError(f"resume: expected the path of a saved level set, got "
                             f"{type(resume).__name__} {resume!r:.60}")
        if grid is not None and not isinstance(grid, Grid):
            raise InputError(f"grid: expected a warpspec.Grid, got {type(grid).__name__} "
                             f"{grid!r:.60}")
        self.scene = scene
        self.alpha = _real("alpha", alpha, low=0.0, high=MAX_ALPHA)
        self.bulge = _real("bulge", bulge, low=-MAX_BULGE, high=MAX_BULGE)
        self.bulge_cap = None if bulge_cap is None else _real("bulge_cap", bulge_cap,
                                                               low=0.0, strict=True)
        self.reinit_every = _non_negative_int("reinit_every", reinit_every)
        self.point_weight = _real("point_weight", point_weight, low=0.0)
        self.gaussian_width = _real("gaussian_width", gaussian_width, low=0.0, strict=True)
        self.normal_radius = _real("normal_radius", normal_radius, low=0.0, strict=True)
        self.cfl = _real("cfl", cfl, low=0.0, strict=True, high=1.0)
        init_iterations = _non_negative_int("init_iterations", init_iterations)
        self.fit_iterations = _non_negative_int("fit_iterations", fit_iterations)
        self.fit_degree = _positive_int("fit_degree", fit_degree)
        if start not in STARTS:
            raise SceneError(f"start: must be one of {', '.join(STARTS)}, got {start!r}")
        self.start = start
        if start == "implicit" and (self.bulge != 0.0 or bulge_cap is not None):
            raise InputError("bulge: bends the paper's plane only; the implicit start needs no "
                             "bulge (pass start='paper' or 'height' to use one)")
        self.fit_report = None
        margin = _real("margin", margin, low=0.0)
        self.narrow_band = None if narrow_band is None else _real(
            "narrow_band", narrow_band, low=3.0)

        resumed = None
        if resume is not None:
            resumed, grid = load_state(resume)
            _check_covers(scene, grid, resume)
        elif grid is None:
            resolution = _positive_int("resolution", resolution)
            lo, hi = scene.bounds(margin=margin)
            grid = Grid.from_bounds(lo, hi, resolution=resolution)
        self.grid = grid
        self.device = resolve_device(device)
        self._check_memory()

        h = grid.spacing
        self.dt = self.cfl * h * h / (6.0 * (1.0 + self.alpha))
        self.w_point = self.point_weight / (h * h)
        eps = self.gaussian_width * h
        self.point_energy_weight = self.w_point * (2.0 * math.pi) ** 1.5 * eps**3
        self.iteration = 0
        self.history: list[dict] = []
        self._graphs: dict = {}
        self._clock = 0.0

        d = self.device
        shape = grid.shape
        origins, dirs = scene.rays()
        codes, vectors = scene.ray_lights()
        m = len(origins)
        self._origin = tuple(float(v) for v in grid.origin)
        self.phi = wp.zeros(shape, dtype=float, device=d)
        self._tmp = wp.zeros(shape, dtype=float, device=d)
        self._gauss = wp.zeros(shape, dtype=float, device=d)
        self._owner = wp.zeros(shape, dtype=int, device=d)
        self._ray_origin = wp.array(origins.astype(np.float32), dtype=wp.vec3, device=d)
        self._ray_dir = wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=d)
        self._light_code = wp.array(codes.astype(np.int32), dtype=int, device=d)
        self._light_vec = wp.array(vectors.astype(np.float32), dtype=wp.vec3, device=d)
        self._hits = wp.zeros(m, dtype=wp.vec3, device=d)
        self._active = wp.zeros(m, dtype=int, device=d)
        self._normals = wp.zeros(m, dtype=wp.vec3, device=d)
        self._ray_index = np.arange(m)  # scene index of each ray the flow uses
        self._points = wp.array(scene.points.astype(np.float32).reshape(-1, 3), dtype=wp.vec3,
                                device=d)
        self._sums = wp.zeros(NUM_SLOTS, dtype=wp.float64, device=d)
        self._redistancer = Redistancer(shape, h, d, band=REINIT_BAND)
        self._good = wp.zeros(shape, dtype=float, device=d)  # last good phi; scratch at start
        self._good_iteration = 0
        self._reinit_count = 0
        self._phi_version = 0  # bumped whenever phi changes; the hits know which they meet
        self._hits_version = -1
        # The ownership pass and the redistancer never run at once: they share a scratch field.
        self._owner_dist = self._redistancer.distance
        self._band = None
        self._band_count = wp.zeros(1, dtype=int, device=d)
        self._band_size = 0
        self.graph = self.device.is_cuda if graph is None else bool(graph)
        if self.narrow_band is not None and self.reinit_every:
            self._band = wp.zeros(grid.size, dtype=int, device=d)

        launch_gaussian(self._points, self._gauss, origin=self._origin, spacing=h,
                        eps=self.gaussian_width * h)
        if resumed is not None:
            self.phi.assign(wp.array(resumed, dtype=float, device=d))
        else:
            self._initialise(init_iterations)
        wp.copy(self._good, self.phi)
        self._rebuild_band()
        self._intersect()

    # -- set-up ---------------------------------------------------------------------------

    def _check_memory(self) -> None:
        need = self.grid.size * BYTES_PER_VOXEL
        if self.device.is_cuda:
            have = int(self.device.free_memory)
        else:
            try:
                have = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
            except (ValueError, OSError, AttributeError):
                have = None
        if have is not None and need > have:
            raise InputError(
                f"resolution: a {'x'.join(map(str, self.grid.shape))} grid needs about "
                f"{need / 2**30:.1f} GiB on {self.device.alias} but only {have / 2**30:.1f} GiB "
                "is free; lower the resolution"
            )

    def _point_distance(self, out: wp.array, cap: float | None) -> None:
        self._redistancer.point_distance(self._points, self._origin, out, cap=cap)

    def _initialise(self, init_iterations: int) -> None:
        h = self.grid.spacing
        point, normal = initial_plane(self.scene, self.grid)
        if self.start == "implicit":
            self._implicit_start(point, normal)
            return
        launch_plane(self.phi, origin=self._origin, spacing=h, point=tuple(point),
                     normal=tuple(normal))
        have_points = self.scene.num_points > 0
        cap = None if self.bulge_cap is None else self.bulge_cap * h
        if init_iterations and have_points:
            dist = self._owner_dist
            self._point_distance(dist, cap)
            dt = 0.5 * h * h / (6.0 * max(float(dist.numpy().max()), h))
            for _ in range(init_iterations):
                launch_init_flow_step(self.phi, dist, self._tmp, spacing=h, dt=dt)
                self.phi, self._tmp = self._tmp, self.phi
            self._redistancer.reinitialize(self.phi)
        if self.bulge != 0.0 and have_points:
            # The scratch field was redistanced since: the distance is computed again.
            self._point_distance(self._owner_dist, cap)
            launch_bend(self.phi, self._owner_dist, self._tmp, spacing=h, c=self.bulge)
            self.phi, self._tmp = self._tmp, self.phi
            self._redistancer.reinitialize(self.phi)
        self.bent_phi = self.phi.numpy().copy()
        if self.start == "height" and self.fit_iterations and self.scene.num_specularities:
            self._fit_start(point, normal)
        self.initial_phi = self.phi.numpy().copy()

    @property
    def default_iterations(self) -> int:
        """Iterations of the flow the automatic schedule gives this grid."""
        return default_iterations(max(self.grid.shape) - 1)

    def _far_cap(self) -> float | None:
        """Voxels beyond which a full redistance may clamp (only the band is ever read).

        With a narrow band the flow, the measures and the band's rebuild read ``phi`` only
        within ``narrow_band`` voxels of the zero set, and the rays only its sign; capping the
        sweeps there makes a full redistance about three times cheaper. Without a band the
        whole grid is updated, and nothing is capped.
        """
        return None if self._band is None else self.narrow_band + FAR_CAP_MARGIN

    def _implicit_start(self, point: np.ndarray, normal: np.ndarray) -> None:
        """Fit the implicit start (any shape) and keep only the rays it accepts."""
        fit = ImplicitStart(self.scene, self.grid, self.device, (point, normal),
                            (self._ray_origin, self._ray_dir, self._light_code, self._light_vec),
                            self._points)
        self.fit_report = fit.run(self.phi)
        self._redistancer.reinitialize(self.phi, cap=self._far_cap())
        self._phi_version += 1
        self.bent_phi = self.phi.numpy().copy()
        self.initial_phi = self.bent_phi
        keep = np.flatnonzero(self.fit_report.weights > 0.0) if self.scene.num_specularities \
            else np.zeros(0, dtype=int)
        if len(keep) < self.scene.num_specularities:
            self._use_rays(keep)

    def _use_rays(self, keep: np.ndarray) -> None:
        """Restrict the flow to the rays ``keep`` (indices into the scene's specularities)."""
        d = self.device
        self._ray_index = keep
        for name in ("_ray_origin", "_ray_dir", "_light_code", "_light_vec"):
            arr = getattr(self, name)
            host = arr.numpy()[keep]
            setattr(self, name, wp.array(host, dtype=arr.dtype, device=d))
        m = len(keep)
        self._hits = wp.zeros(m, dtype=wp.vec3, device=d)
        self._active = wp.zeros(m, dtype=int, device=d)
        self._normals = wp.zeros(m, dtype=wp.vec3, device=d)

    def _fit_start(self, point: np.ndarray, normal: np.ndarray) -> None:
        """Refine the start with a height field fitted to the points and the normals.

        The normals are taken where the rays meet the current start; the field is
        re-intersected and refitted ``fit_iterations`` times, its degree rising from 2 (a
        gentle quadric first: slopes read where the rays meet a poor start sit in the wrong
        places, and a high degree overfits them).
        """
        frame = plane_frame(normal)
        scale = 0.5 * float(np.max(self.grid.upper - self.grid.origin))
        d = self.device
        previous, fitted = self._good, self._tmp
        self._intersect()  # each accepted round ends with the rays intersected again
        changed = False
        for round_ in range(self.fit_iterations):
            ok = self._active.numpy() == 1
            if ok.sum() < 3:
                break
            fit = fit_height_field(point, frame, scale, self.scene.points,
                                   self._hits.numpy()[ok].astype(np.float64),
                                   self._normals.numpy()[ok].astype(np.float64),
                                   degree=min(self.fit_degree, 2 + round_))
            launch_height_field(
                fitted, wp.array(fit.coefficient_matrix().astype(np.float32), dtype=float,
                                 device=d),
                origin=self._origin, spacing=self.grid.spacing, point=tuple(point),
                axes=tuple(tuple(r) for r in frame), scale=scale)
            wp.copy(previous, self.phi)
            # Damped fixed point: a fit made from intersections far from the truth can
            # overshoot until the rays miss; halve the step until no ray is lost. The rays
            # march by sign in half-cell steps, so the blends need no redistancing until the
            # last one is kept.
            accepted = False
            for beta in (1.0, 0.5, 0.25, 0.125):
                launch_blend(previous, fitted, self.phi, beta=beta)
                self._intersect()
                if self._active.numpy().sum() >= ok.sum():
                    accepted = changed = True
                    break
            if not accepted:
                wp.copy(self.phi, previous)
                break
        if changed:
            self._redistancer.reinitialize(self.phi)
            self._phi_version += 1

    # -- iteration ------------------------------------------------------------------------

    def _intersect(self) -> None:
        launch_intersect(self.phi, self._ray_origin, self._ray_dir, self._light_code,
                         self._light_vec, self._hits, self._active, self._normals,
                         origin=self._origin, spacing=self.grid.spacing)
        launch_claim_normals(self._hits, self._active, self._owner_dist, self._owner,
                             origin=self._origin, spacing=self.grid.spacing,
                             radius=self.normal_radius * self.grid.spacing)
        self._hits_version = self._phi_version

    def _current_hits(self) -> None:
        """Intersect the rays unless they already meet this ``phi`` (measures, then a step)."""
        if self._hits_version != self._phi_version:
            self._intersect()

    def _rebuild_band(self) -> None:
        """Collect the narrow band around the current zero set.

        Both buffers of the ping-pong pair get the current ``phi``: the band step writes only
        the band, so every other node must agree in both.
        """
        if self._band is None:
            return
        wp.copy(self._tmp, self.phi)
        launch_build_band(self.phi, self._band, self._band_count,
                          width=self.narrow_band * self.grid.spacing)
        # On the CPU the launch is synchronous and the count costs nothing to read; on CUDA
        # the band kernels run at full capacity and skip the threads past the count.
        if self.device.is_cpu:
            self._band_size = int(self._band_count.numpy()[0])
        else:
            self._band_size = self._band.shape[0]

    def _reinitialize(self) -> None:
        """Check ``phi``, redistance it, rebuild the band and keep it as the last good state.

        Raises:
            ReconstructionError: If ``phi`` holds a non-finite value; the last good state is
                restored first.
        """
        self._check_finite()
        self._reinit_count += 1
        if self._band is None or self._reinit_count % FULL_REINIT_EVERY == 0:
            self._redistancer.reinitialize(self.phi, cap=self._far_cap())
        else:
            # Only the band changes between reinitialisations: redistance it alone. Far nodes
            # keep old distances, whose error grows as the surface moves; every
            # FULL_REINIT_EVERY-th time the whole grid is redone.
            self._redistancer.reinitialize_band(self.phi, self._band, self._band_count,
                                                size=self._band_size,
                                                width=self.narrow_band + 2.0)
        self._phi_version += 1
        self._rebuild_band()
        wp.copy(self._good, self.phi)
        self._good_iteration = self.iteration

    def _reduce(self) -> np.ndarray:
        launch_measures(self.phi, self._owner, self._normals, self._hits, self._active,
                        self._points, self._sums, origin=self._origin, spacing=self.grid.spacing,
                        band=self._band, count=self._band_count, size=self._band_size)
        return self._sums.numpy()

    def _check_finite(self, sums: np.ndarray | None = None) -> None:
        sums = self._reduce() if sums is None else sums
        bad = int(sums[MEASURE_SLOTS["nonfinite"]])
        if bad == 0:
            return
        failed = self.iteration
        wp.copy(self.phi, self._good)
        wp.copy(self._tmp, self._good)
        self.iteration = self._good_iteration
        self._phi_version += 1
        self.history = [m for m in self.history if m["iteration"] <= self.iteration]
        self._rebuild_band()
        raise ReconstructionError(
            f"iteration {failed}: phi has {bad} non-finite values; the solver is back at the "
            f"state of iteration {self._good_iteration}; lower cfl or point_weight"
        )

    def step(
        self, *, normal: bool = True, smooth: bool = True, points: bool = True,
        intersect: bool = True,
    ) -> None:
        """Advance one iteration: intersect the rays, take one flow step, reinitialise on time.

        Args:
            normal: Include the normal term.
            smooth: Include the smoothness term.
            points: Include the point term.
            intersect: Recompute the ray intersections first (``False`` keeps the last ones:
                the flow then descends the normal energy of a fixed set of intersections).
        """
        if normal and smooth and points and intersect and self.graph:
            key = (id(self.phi), self._band_size)
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
                self._current_hits()
            self._launch_step(normal, smooth, points, False)
        self.phi, self._tmp = self._tmp, self.phi
        self._phi_version += 1
        self.iteration += 1
        if self.reinit_every and self.iteration % self.reinit_every == 0:
            self._reinitialize()

    def _launch_step(self, normal: bool, smooth: bool, points: bool, intersect: bool) -> None:
        """The launches of one iteration, from ``phi`` into its ping-pong twin."""
        if intersect:
            self._intersect()
        weights = {
            "spacing": self.grid.spacing,
            "dt": self.dt,
            "normal_weight": 1.0 if normal else 0.0,
            "alpha": self.alpha if smooth else 0.0,
            "point_weight": self.w_point if points else 0.0,
        }
        if self._band is None:
            launch_flow_step(self.phi, self._owner, self._normals, self._gauss, self._tmp,
                             **weights)
        else:
            launch_flow_step_band(self.phi, self._owner, self._normals, self._gauss,
                                  self._band, self._band_count, self._tmp,
                                  size=self._band_size, **weights)

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
            self._current_hits()
        s = self._reduce()
        self._check_finite(s)
        active = int(s[MEASURE_SLOTS["active"]])
        npts = max(self.scene.num_points, 1)
        e_n = float(s[MEASURE_SLOTS["energy_normal"]])
        # E_P = sum |phi(y)|, weighted as the flow weighs it: w_P times the Gaussian's volume.
        e_p = self.point_energy_weight * float(s[MEASURE_SLOTS["point_abs_sum"]])
        e_s = float(s[MEASURE_SLOTS["energy_smooth"]])
        return {
            "iteration": self.iteration,
            "normal_error": float(s[0] / active) if active else float("nan"),
            "point_error": float(s[3] / npts / self.grid.spacing) if self.scene.num_points
            else float("nan"),
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
        measure_every: int = 0,
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
        iterations = _positive_int("iterations", iterations)
        measure_every = _non_negative_int("measure_every", measure_every)
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

    def phi_numpy(self) -> np.ndarray:
        """A host copy of the current level set."""
        return self.phi.numpy().copy()

    def result(self, *, crop: bool = True) -> Result:
        """The current surface as a :class:`Result` (mesh, level set, grid, history).

        Args:
            crop: Crop an open surface to where the data reaches: the faces inside the convex
                hull of the rays' hits and the points, grown by the median gap between them
                (at least three voxels)
                (:func:`warpspec.mesh.crop_to_data_hull`); beyond it the surface is the fit's
                extrapolation, which no constraint speaks for. A closed surface is never
                cropped. ``False`` keeps the whole zero set.

        Raises:
            ReconstructionError: If the zero set has left the domain (no surface to mesh).
        """
        phi = self.phi.numpy().copy()
        self._current_hits()
        used = self._hits.numpy().astype(np.float64)
        used[self._active.numpy() == 0] = np.nan
        hits = np.full((self.scene.num_specularities, 3), np.nan)
        hits[self._ray_index] = used
        if self._band is not None and self.narrow_band >= 2.0:
            # on the device, over the band's cells: no full grid through marching cubes
            vertices, faces = triangulate_device(self.phi, self.grid, band=self._band,
                                                 count=self._band_count)
        else:
            vertices, faces = triangulate(phi, self.grid)
        anchors = np.vstack([hits[np.all(np.isfinite(hits), axis=1)],
                             self.scene.points.reshape(-1, 3)])
        vertices, faces = supported_components(vertices, faces, anchors,
                                               radius=SUPPORT_RADIUS * self.grid.spacing)
        if crop and is_open(faces):
            # between anchors a curved surface bulges past their hull by up to about the gap
            # between neighbours: the margin is that gap, at least SUPPORT_RADIUS voxels
            h = self.grid.spacing
            margin = data_crop_limit(anchors, h, floor=SUPPORT_RADIUS, spread=1.0) * h
            vertices, faces = crop_to_data_hull(vertices, faces, anchors, margin=margin)
        rejected = ([] if self.fit_report is None
                    else rejected_summary(self.fit_report, self.scene))
        result = Result(vertices=vertices, faces=faces, phi=phi, grid=self.grid,
                        history=list(self.history), hits=hits, rejected=rejected)
        result.assess(self.scene)
        return result


# Device bytes per voxel: phi, its ping-pong twin, the last good phi, G, owner and the narrow
# band's list (4 each), and the redistancer's scratch (5, shared with the ownership pass).
BYTES_PER_VOXEL = 29


def reconstruct(scene: Scene | str | os.PathLike, *, iterations: int | None = None,
                **options) -> Result:
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
