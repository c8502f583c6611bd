"""The paper's experiments on synthetic scenes with known truth: run, score, draw, tabulate.

Shared by ``sphere_octant.py``, ``car_window.py`` and ``wine_bottle.py``; run on its own it
reproduces the whole results table of docs/RESULTS.md:

    python examples/experiments.py                       # every setup, 64^3, 300 iterations
    python examples/experiments.py --setups octant car-window --iterations 100

How each figure of the table is defined (see also ``warpspec evaluate --help``):

- completeness / accuracy: mean distance from the truth mesh to the reconstructed mesh /
  from the reconstructed mesh to the truth, over area-uniform samples (20000 per mesh plus
  the vertices, exact closest points), restricted to the region the constraints cover (the
  2D convex hull of the true specular points and the point constraints on their best-fit
  plane), in voxel widths h (the longest side of the scene's domain / resolution).
- Chamfer: the symmetric mean (accuracy + completeness) / 2.
- normal angle: at each true specular point, the angle between the true normal and the normal
  of the closest face of the reconstructed mesh; mean and max in degrees.
- 1 - N.n: the solver's mean of 1 - N_i . n(x_i) over the rays that meet the surface, after
  the last iteration (paper Figure 5a).
- point error: the solver's mean |phi(y)| over the point constraints in voxel widths, after
  the last iteration (paper Figure 5b; a signed distance right after a reinitialisation).
- misses: rays that do not meet the final surface inside the domain.
- time: wall-clock seconds from building the solver (start surface included) to the mesh,
  with the measures recorded at every iteration; kernels already compiled.

matplotlib is needed only for the figures (``pip install 'warpspec[plot]'``).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpspec import Reconstructor, SceneError
from warpspec.evaluate import (
    Evaluation,
    closest_point,
    crop_mesh,
    evaluate,
    mesh_normals_at,
    truth_region,
)
from warpspec.mesh import extract_mesh, sample_trilinear
from warpspec.solver import initial_plane
from warpspec.synthetic import SyntheticScene, make_scene

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "figures"

#: Targets of issue 3: mean truth-to-mesh distance (voxels) and mean normal angle (degrees).
TARGET_DISTANCE = 0.5
TARGET_DISTANCE_NOISY = 0.75
TARGET_ANGLE = 2.0


@dataclass(frozen=True)
class Setup:
    """One experiment: a built-in scene, its corruption and the solver's options.

    Attributes:
        label: Name in the tables.
        scene: Built-in scene name (:func:`warpspec.synthetic.make_scene`).
        options: Keyword options of :class:`warpspec.Reconstructor`.
        noise: Pixel noise (standard deviation, pixels).
        seed: Seed of the noise.
        note: What the setup reproduces.
    """

    label: str
    scene: str
    options: dict = field(default_factory=dict)
    noise: float = 0.0
    seed: int = 0
    note: str = ""

    @property
    def target_distance(self) -> float:
        """The completeness target of issue 3 for this setup, in voxel widths."""
        return TARGET_DISTANCE_NOISY if self.noise > 0 else TARGET_DISTANCE


SETUPS: dict[str, Setup] = {s.label: s for s in (
    Setup("octant-paper", "octant", {"start": "paper", "bulge": 0.5},
          note="paper section 4.2: plane through the 3 points, bent with c = 0.5"),
    Setup("octant", "octant", {},
          note="warpspec's default options (the implicit start, no bulge)"),
    Setup("octant-noise", "octant", {}, noise=0.5, seed=0,
          note="octant with 0.5 px Gaussian noise on every highlight"),
    Setup("ellipsoid-cap-paper", "ellipsoid-cap", {"start": "paper"},
          note="the plane through the 4 rim points, as the paper would start"),
    Setup("ellipsoid-cap", "ellipsoid-cap", {},
          note="20 highlights of a point lamp, 4 points on the rim"),
    Setup("car-window-paper", "car-window", {"start": "paper", "bulge": 0.3,
                                             "bulge_cap": 3.0},
          note="paper section 4.1: plane bent with c = 0.3, d_max = 3 voxels"),
    Setup("car-window", "car-window", {},
          note="38 normals, 2 corners, sun; default options"),
    Setup("wine-bottle-paper", "wine-bottle", {"start": "paper"},
          note="the plane through the 4 label corners, as the paper would start"),
    Setup("wine-bottle", "wine-bottle", {},
          note="11 views along an arc, camera flash, 4 label corners (paper 4.1)"),
)}

#: View (elevation, azimuth in degrees) of each scene in the figures.
VIEWS: dict[str, tuple[float, float]] = {
    "octant": (18.0, 15.0),
    "ellipsoid-cap": (30.0, -60.0),
    "car-window": (20.0, -35.0),
    "wine-bottle": (15.0, 55.0),
}

#: File-name stem of each scene's figures.
FIGURE_STEMS = {"octant": "octant", "ellipsoid-cap": "ellipsoid_cap",
                "car-window": "car_window", "wine-bottle": "wine_bottle"}


def is_paper_start(setup: Setup) -> bool:
    """Whether a setup starts as the paper does (plane and bend)."""
    return setup.options.get("start") == "paper"


def run_label(exp: Experiment) -> str:
    """Legend of a run in the figures: which start, and the noise."""
    label = "paper start" if is_paper_start(exp.setup) else "default start"
    return label + (f", {exp.setup.noise:g} px noise" if exp.setup.noise else "")


@dataclass
class Experiment:
    """A finished run and its scores.

    Attributes:
        setup: What was run.
        synthetic: The scene with its ground truth.
        solver: The solver after the run; its ``initial_phi`` is a copy of the start taken
            before the flow (on the CPU its ``bent_phi`` aliases a reused buffer: use the
            ``-paper`` twin's ``initial_phi`` for the paper's start).
        result: The solver's result (mesh, phi, history, hits).
        evaluation: The final mesh against the truth (see the module docstring).
        start: The start surface (after the fit, before the flow) against the truth.
        seconds: Wall-clock time from building the solver to the mesh.
        resolution: Cells along the domain's longest side.
        iterations: Iterations of the flow.
    """

    setup: Setup
    synthetic: SyntheticScene
    solver: Reconstructor
    result: object
    evaluation: Evaluation
    start: Evaluation | None
    seconds: float
    resolution: int
    iterations: int

    @property
    def spacing(self) -> float:
        """Voxel width h."""
        return self.result.grid.spacing

    @property
    def last(self) -> dict:
        """The solver's measures after the last iteration."""
        return self.result.history[-1]

    @property
    def completeness(self) -> float:
        """Mean truth-to-mesh distance in voxel widths."""
        return self.evaluation.completeness.mean / self.spacing

    @property
    def accuracy(self) -> float:
        """Mean mesh-to-truth distance in voxel widths."""
        return self.evaluation.accuracy.mean / self.spacing

    @property
    def angle(self) -> float:
        """Mean normal angle at the true specular points, degrees."""
        return float(self.evaluation.normal_angle_mean)

    def meets(self) -> tuple[bool, bool]:
        """Whether the distance target and the angle target of issue 3 are met."""
        return (self.completeness <= self.setup.target_distance, self.angle <= TARGET_ANGLE)


# --------------------------------------------------------------------------------------------
# Running and scoring
# --------------------------------------------------------------------------------------------


def inlier_truth(synthetic: SyntheticScene) -> tuple[np.ndarray, np.ndarray]:
    """True specular points and normals of the highlights that are not outliers."""
    keep = synthetic.inliers
    return synthetic.truth_points[keep], synthetic.truth_normals[keep]


def score(mesh, synthetic: SyntheticScene, spacing: float, *, samples: int = 20_000
          ) -> Evaluation:
    """Evaluate a mesh against the scene's truth inside the constraints' hull.

    The region is the hull of the true specular points and the point constraints (the same
    for every reconstruction of the scene); the normal angle is taken at the true specular
    points against the exact true normals.
    """
    points, normals = inlier_truth(synthetic)
    region = truth_region(points, synthetic.points)
    return evaluate(mesh, synthetic.truth_mesh(), spacing=spacing, region=region,
                    specular_points=points, true_normals=normals, samples=samples)


_WARM: set = set()


def warm_up(device: str | None) -> None:
    """Compile (or load) every kernel once, so that no run's time includes compilation."""
    key = str(device)
    if key in _WARM:
        return
    scene = make_scene("octant").scene()
    solver = Reconstructor(scene, resolution=12, device=device, start="paper", bulge=0.5,
                           reinit_every=1)
    solver.run(2)
    solver.result()
    _WARM.add(key)


def run_setup(
    setup: Setup | str,
    *,
    resolution: int = 64,
    iterations: int = 300,
    device: str | None = None,
    measure_every: int = 1,
    samples: int = 20_000,
    score_start: bool = True,
    band: str | None = None,
    **overrides,
) -> Experiment:
    """Build the scene, run the solver, score the start and the result.

    Args:
        setup: A :class:`Setup` or the label of one in :data:`SETUPS`.
        resolution: Cells along the domain's longest side.
        iterations: Iterations of the flow.
        device: Warp device (default: CUDA when present).
        measure_every: Record the solver's measures every this many iterations.
        samples: Area samples per mesh for the scores.
        score_start: Also score the start surface (after the fit, before the flow).
        band: Diagnostic only: initialise the reinitialisation's frozen band this way
            (``"gradient"``, the solver's choice, or ``"axis"``, DESIGN section 6); see
            :func:`redistancer_band`.
        **overrides: Solver options that replace the setup's.
    """
    if isinstance(setup, str):
        if setup not in SETUPS:
            raise SceneError(f"setup: unknown {setup!r}; expected one of {list(SETUPS)}")
        setup = SETUPS[setup]
    synthetic = make_scene(setup.scene, noise=setup.noise, seed=setup.seed)
    scene = synthetic.scene()
    options = {**setup.options, **overrides}
    warm_up(device)
    start = time.perf_counter()
    with redistancer_band(band):
        solver = Reconstructor(scene, resolution=resolution, device=device, **options)
    # On the CPU, Warp's .numpy() is a view of the device array, and the solver reuses its
    # buffers: keep a copy of the start before the flow overwrites it.
    solver.initial_phi = np.array(solver.initial_phi, copy=True)
    solver.run(iterations, measure_every=measure_every)
    result = solver.result()
    seconds = time.perf_counter() - start
    h = result.grid.spacing
    evaluation = score(result.mesh, synthetic, h, samples=samples)
    start_eval = None
    if score_start:
        start_eval = score(extract_mesh(solver.initial_phi, solver.grid), synthetic, h,
                           samples=samples)
    return Experiment(setup=setup, synthetic=synthetic, solver=solver, result=result,
                      evaluation=evaluation, start=start_eval, seconds=seconds,
                      resolution=resolution, iterations=iterations)


@contextlib.contextmanager
def redistancer_band(band: str | None):
    """Diagnostic: build the solver's reinitialisation with another band initialisation.

    The solver freezes the nodes next to the zero set at ``|phi| / |grad phi|`` (at most the
    nearest axis crossing; band ``"gradient"``). Inside this context it gets ``band=band``
    instead; ``"axis"`` is the per-axis formula ``1 / sqrt(sum over axes of 1 / d_axis^2)`` of
    DESIGN section 6. This patches a name inside ``warpspec.solver``; it is not an option of
    the solver.
    """
    if band is None:
        yield
        return
    import warpspec.solver as solver_module

    original = solver_module.Redistancer

    def forced(*args, **kwargs):
        return original(*args, **{**kwargs, "band": band})

    solver_module.Redistancer = forced
    try:
        yield
    finally:
        solver_module.Redistancer = original


def diagnostics(exp: Experiment) -> dict[str, float]:
    """Numbers that say why a run does or does not meet the targets.

    - ``hit_offset``: mean distance (voxels) from where each ray meets the final surface to
      the true specular point on that ray (the depth error along the rays);
    - ``grad_angle``: mean angle (deg) between ``grad phi`` (central differences, trilinear)
      at the true specular points and the true normals: the solver's own normal;
    - ``vertex_angle``: mean angle (deg) with the barycentric interpolation of the mesh's
      vertex normals at the closest points (what a shaded render shows);
    - ``face_angle_start`` and ``completeness_start``: the same figures for the start surface.
    """
    syn = exp.synthetic
    points, normals = inlier_truth(syn)
    h = exp.spacing
    hits = exp.result.hits[syn.inliers]
    ok = np.all(np.isfinite(hits), axis=1)
    offset = np.linalg.norm(hits[ok] - points[ok], axis=1) / h
    grads = np.gradient(exp.result.phi.astype(np.float64), h)
    g = np.stack([sample_trilinear(gi, exp.result.grid, points) for gi in grads], axis=1)
    vn = mesh_normals_at(exp.result.mesh, points, mode="vertex")
    out = {
        "hit_offset": float(offset.mean()) if len(offset) else float("nan"),
        "hit_offset_max": float(offset.max()) if len(offset) else float("nan"),
        "grad_angle": float(_angles(g, normals).mean()),
        "vertex_angle": float(_angles(vn, normals).mean()),
    }
    if exp.start is not None:
        out["completeness_start"] = exp.start.completeness.mean / h
        out["face_angle_start"] = float(exp.start.normal_angle_mean)
    first = exp.result.history[0]
    out["normal_error_start"] = first["normal_error"]
    out["point_error_start"] = first["point_error"]
    return out


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1),
                                 np.einsum("ij,ij->i", a, b)))


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------

TABLE_HEADER = (
    "| scene | constraints | resolution | iterations | time (s) | completeness (h) "
    "| accuracy (h) | normal angle mean / max (deg) | 1 - N.n | point error (h) | misses "
    "| targets |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|"
)

DIAGNOSTIC_HEADER = (
    "| scene | start: completeness (h) | start: normal angle (deg) | start: 1 - N.n "
    "| end: completeness (h) | end: normal angle, faces (deg) | end: vertex normals (deg) "
    "| end: grad phi (deg) | ray depth error mean / max (h) |\n"
    "|---|---|---|---|---|---|---|---|---|"
)


def table_row(exp: Experiment) -> str:
    """The results-table row of an experiment (markdown)."""
    syn, last = exp.synthetic, exp.last
    dist_ok, angle_ok = exp.meets()
    n_out = int(syn.outlier_mask.sum())
    cons = f"{len(syn.truth_points)} normals, {len(syn.points)} points"
    if exp.setup.noise:
        cons += f", {exp.setup.noise:g} px noise"
    if n_out:
        cons += f", {n_out} outliers"
    verdict = ("distance " + ("met" if dist_ok else "MISSED") + ", angle "
               + ("met" if angle_ok else "MISSED"))
    return (
        f"| {exp.setup.label} | {cons} | {exp.resolution} | {exp.iterations} "
        f"| {exp.seconds:.1f} | {exp.completeness:.3f} | {exp.accuracy:.3f} "
        f"| {exp.angle:.2f} / {exp.evaluation.normal_angle_max:.2f} "
        f"| {last['normal_error']:.2e} | {last['point_error']:.3f} | {last['misses']} "
        f"| {verdict} |"
    )


def diagnostic_row(exp: Experiment) -> str:
    """The diagnostics row of an experiment (markdown, see :func:`diagnostics`)."""
    d = diagnostics(exp)
    return (
        f"| {exp.setup.label} | {d.get('completeness_start', float('nan')):.3f} "
        f"| {d.get('face_angle_start', float('nan')):.2f} | {d['normal_error_start']:.2e} "
        f"| {exp.completeness:.3f} | {exp.angle:.2f} | {d['vertex_angle']:.2f} "
        f"| {d['grad_angle']:.2f} | {d['hit_offset']:.2f} / {d['hit_offset_max']:.2f} |"
    )


#: Variants run by :func:`ablation`: solver options, or the band of the reinitialisation.
ABLATIONS: dict[str, dict] = {
    "as in the table": {},
    "no reinitialisation": {"reinit_every": 0},
    "band 'axis' (DESIGN 6)": {"band": "axis"},
}

ABLATION_HEADER = (
    "| scene | variant | completeness (h) | normal angle mean / max (deg) | 1 - N.n "
    "| point error (h) | ray depth error mean (h) |\n"
    "|---|---|---|---|---|---|---|"
)


def ablation(label: str, *, resolution: int = 64, iterations: int = 300,
             device: str | None = None, variants: Sequence[str] | None = None) -> list[str]:
    """Rows of the ablation table: one setup under each variant of :data:`ABLATIONS`."""
    rows = []
    for name in variants or list(ABLATIONS):
        options = dict(ABLATIONS[name])
        exp = run_setup(label, resolution=resolution, iterations=iterations, device=device,
                        score_start=False, **options)
        d = diagnostics(exp)
        last = exp.last
        rows.append(
            f"| {label} | {name} | {exp.completeness:.3f} "
            f"| {exp.angle:.2f} / {exp.evaluation.normal_angle_max:.2f} "
            f"| {last['normal_error']:.2e} | {last['point_error']:.3f} "
            f"| {d['hit_offset']:.2f} |"
        )
        print(rows[-1], file=sys.stderr, flush=True)
    return rows


# --------------------------------------------------------------------------------------------
# Figures (matplotlib, imported lazily, drawn on the Agg canvas without pyplot)
# --------------------------------------------------------------------------------------------


def _figure(width: float, height: float):
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover - depends on the environment
        raise SystemExit("the figures need matplotlib: pip install 'warpspec[plot]'") from None
    fig = Figure(figsize=(width, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def _view_direction(elev: float, azim: float) -> np.ndarray:
    e, a = math.radians(elev), math.radians(azim)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def render_panels(
    panels: Sequence[tuple[str, object, np.ndarray | None]],
    path: Path,
    *,
    elev: float,
    azim: float,
    bounds: tuple[np.ndarray, np.ndarray],
    points: np.ndarray | None = None,
    columns: int | None = None,
    colour_limit: float = 2.0,
    title: str = "",
) -> Path:
    """Render meshes side by side as a PNG: shaded, or coloured by a value per face.

    Args:
        panels: ``(title, mesh, values)``; ``values`` (one per face, e.g. the distance to the
            truth in voxel widths) colours the faces instead of plain shading.
        path: The PNG to write.
        elev: Elevation of the view, degrees.
        azim: Azimuth of the view, degrees.
        bounds: The box to show ``(min, max)``, the same in every panel.
        points: Points drawn in every panel (the point constraints).
        columns: Panels per row (default: all in one row).
        colour_limit: Values at or above this get the last colour of the map.
        title: Title of the figure.
    """
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    columns = columns or len(panels)
    rows = math.ceil(len(panels) / columns)
    fig = _figure(3.3 * columns, 3.3 * rows + (0.4 if title else 0.0))
    view = _view_direction(elev, azim)
    light = view + np.array([0.0, 0.0, 0.6])
    light /= np.linalg.norm(light)
    cmap = colormaps["viridis"]
    norm = Normalize(0.0, colour_limit)
    lo, hi = bounds
    mapped = None
    for k, (name, mesh, values) in enumerate(panels):
        ax = fig.add_subplot(rows, columns, k + 1, projection="3d")
        tri = np.asarray(mesh.triangles)
        shade = 0.35 + 0.65 * np.abs(np.asarray(mesh.face_normals) @ light)
        if values is None:
            colours = np.clip(np.outer(shade, [0.62, 0.72, 0.86]), 0, 1)
        else:
            colours = cmap(norm(np.asarray(values)))[:, :3] * shade[:, None]
            mapped = True
        # Edges in the face colour hide the seams that anti-aliasing leaves between faces.
        ax.add_collection3d(Poly3DCollection(tri, facecolors=colours, edgecolors=colours,
                                             linewidths=0.3))
        if points is not None and len(points):
            ax.scatter(*np.asarray(points).T, color="#d62728", s=18, depthshade=False)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
        ax.set_title(name, fontsize=9)
    if mapped:
        from matplotlib.cm import ScalarMappable

        sm = ScalarMappable(norm=norm, cmap=cmap)
        cax = fig.add_axes((0.88, 0.15, 0.015, 0.6))
        fig.colorbar(sm, cax=cax, label="distance to truth (voxels)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0.0, right=0.84 if mapped else 1.0, bottom=0.0, top=0.9,
                        wspace=0.0, hspace=0.05)
    path = Path(path)
    fig.savefig(path)
    return path


def distance_per_face(mesh, truth, spacing: float) -> np.ndarray:
    """Distance from each face centre of ``mesh`` to ``truth``, in voxel widths."""
    _, d, _, _ = closest_point(truth, np.asarray(mesh.triangles_center))
    return d / spacing


def plot_convergence(
    runs: Sequence[tuple[str, list[dict]]],
    path: Path,
    *,
    reinit_every: int = 10,
    title: str = "",
) -> Path:
    """The paper's Figure 5 as a PNG: mean 1 - N.n and mean |phi(S)| per iteration.

    Args:
        runs: ``(label, history)`` pairs.
        path: The PNG to write.
        reinit_every: The reinitialisation period; as in the paper, the point error is drawn
            at the iterations right after a reinitialisation (where phi is a distance), and
            faintly at every other recorded iteration.
        title: Title of the figure.
    """
    fig = _figure(10.0, 3.6)
    ax_n = fig.add_subplot(1, 2, 1)
    ax_p = fig.add_subplot(1, 2, 2)
    for k, (label, history) in enumerate(runs):
        colour = f"C{k}"
        it = np.array([m["iteration"] for m in history])
        ne = np.array([m["normal_error"] for m in history], dtype=float)
        pe = np.array([m["point_error"] for m in history], dtype=float)
        ax_n.plot(it, ne, color=colour, label=label)
        ax_p.plot(it, pe, color=colour, alpha=0.25, linewidth=0.8)
        at = (it % reinit_every == 0) if reinit_every else np.ones(len(it), dtype=bool)
        ax_p.plot(it[at], pe[at], "o-", color=colour, markersize=3, label=label)
    ax_n.set_yscale("log")
    ax_n.set_xlabel("iteration")
    ax_n.set_ylabel("mean 1 - N.n over active rays")
    ax_n.set_title("(a) normal constraints", fontsize=10)
    ax_p.set_xlabel("iteration")
    ax_p.set_ylabel("mean |phi(S)| (voxels)")
    ax_p.set_title("(b) point constraints (dots: right after a reinitialisation)", fontsize=10)
    for ax in (ax_n, ax_p):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path


def view_box(synthetic: SyntheticScene, pad: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A box around the truth patch, grown by ``pad`` of its longest side, with equal axes."""
    v = np.asarray(synthetic.truth_mesh().vertices)
    lo, hi = v.min(axis=0), v.max(axis=0)
    grow = pad * float(np.max(hi - lo))
    return lo - grow, hi + grow


def crop_for_display(mesh, synthetic: SyntheticScene, margin: float):
    """The part of ``mesh`` inside the constraints' hull grown by ``margin`` (world units)."""
    points, _ = inlier_truth(synthetic)
    return crop_mesh(mesh, truth_region(points, synthetic.points, margin=margin))


def plane_phi(exp: Experiment) -> np.ndarray:
    """The initial plane of a run (before any bend or fit) as a signed distance on its grid."""
    grid = exp.solver.grid
    point, normal = initial_plane(exp.synthetic.scene(), grid)
    x, y, z = grid.coordinates()
    return ((x - point[0]) * normal[0] + (y - point[1]) * normal[1]
            + (z - point[2]) * normal[2]).astype(np.float32)


def figure_starts(paper: Experiment, fitted: Experiment, path: Path, *,
                  title: str = "") -> Path:
    """The paper's Figure 4 for any scene: starts, truth and results, as one PNG.

    Panels: the initial plane; the bent plane (when the setup bends it); the truth; the
    result from the paper's start; warpspec's fitted start; the result from it. Surfaces are
    cropped to the constraints' hull; all but the plane and the truth are coloured by their
    distance to the truth in voxel widths.
    """
    syn, h = paper.synthetic, paper.spacing
    truth = syn.truth_mesh()

    def cropped(phi):
        return crop_for_display(extract_mesh(phi, paper.solver.grid), syn, 0.0)

    def coloured(mesh):
        return distance_per_face(mesh, truth, h)

    bulge = paper.setup.options.get("bulge", 0.0)
    cap = paper.setup.options.get("bulge_cap")
    res_paper = crop_for_display(paper.result.mesh, syn, 0.0)
    start = cropped(fitted.solver.initial_phi)
    res_fit = crop_for_display(fitted.result.mesh, syn, 0.0)
    panels = [("initial plane", cropped(plane_phi(paper)), None)]
    if bulge:
        bent = cropped(paper.solver.initial_phi)
        panels.append((f"bent, c = {bulge:g}" + (f", d_max = {cap:g} h" if cap else ""),
                       bent, coloured(bent)))
    panels += [
        ("truth", truth, None),
        (f"result from the paper's start, {paper.iterations} it.", res_paper,
         coloured(res_paper)),
        ("fitted start", start, coloured(start)),
        (f"result from the fitted start, {fitted.iterations} it.", res_fit, coloured(res_fit)),
    ]
    panels = [(f"({chr(97 + k)}) {name}", mesh, values)
              for k, (name, mesh, values) in enumerate(panels)]
    elev, azim = VIEWS.get(syn.name, (20.0, -60.0))
    return render_panels(panels, path, elev=elev, azim=azim, bounds=view_box(syn),
                         points=syn.points, columns=3, colour_limit=2.0, title=title)


def scene_figures(runs: Sequence[Experiment], out_dir: Path) -> list[Path]:
    """Draw the figures of every scene whose paper-start and fitted-start runs are in ``runs``.

    For a scene stem ``S``: ``S_fig4.png`` (:func:`figure_starts`) and ``S_fig5.png`` (the
    convergence of every run of that scene, :func:`plot_convergence`).
    """
    written = []
    for scene, stem in FIGURE_STEMS.items():
        mine = [e for e in runs if e.setup.scene == scene]
        paper = next((e for e in mine if is_paper_start(e.setup)), None)
        fitted = next((e for e in mine if not is_paper_start(e.setup) and not e.setup.noise),
                      None)
        if paper is None or fitted is None:
            continue
        grid = f"{paper.resolution}^3 grid"
        written.append(figure_starts(paper, fitted, out_dir / f"{stem}_fig4.png",
                                     title=f"{scene}, {grid}: starts and results"))
        written.append(plot_convergence(
            [(run_label(e), e.result.history) for e in mine], out_dir / f"{stem}_fig5.png",
            reinit_every=fitted.solver.reinit_every,
            title=f"{scene}, {grid}: convergence"))
    return written


# --------------------------------------------------------------------------------------------
# Command line shared by the examples
# --------------------------------------------------------------------------------------------


def example_parser(description: str) -> argparse.ArgumentParser:
    """The options every example takes."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out-dir", type=Path, default=DEFAULT_OUT,
                        help="folder for the PNG figures (default: docs/figures)")
    parser.add_argument("--resolution", type=int, default=64,
                        help="cells along the domain's longest side (default 64)")
    parser.add_argument("--iterations", type=int, default=300,
                        help="iterations of the flow (default 300)")
    parser.add_argument("--device", default=None,
                        help="Warp device: cpu, cuda, cuda:0 (default: CUDA if present)")
    return parser


def check_args(args: argparse.Namespace) -> None:
    """Exit with a one-line message when an example's options are out of range."""
    if args.resolution < 8:
        raise SystemExit(f"--resolution: must be at least 8, got {args.resolution}")
    if args.iterations < 1:
        raise SystemExit(f"--iterations: must be positive, got {args.iterations}")
    if not args.out_dir.is_dir():
        args.out_dir.mkdir(parents=True, exist_ok=True)


def print_table(experiments: Sequence[Experiment], *, file=None) -> None:
    """Print the results table and the diagnostics table (markdown)."""
    file = file or sys.stdout
    print(TABLE_HEADER, file=file)
    for exp in experiments:
        print(table_row(exp), file=file)
    print(file=file)
    print(DIAGNOSTIC_HEADER, file=file)
    for exp in experiments:
        print(diagnostic_row(exp), file=file)


def scene_example(labels: Sequence[str], description: str, *,
                  argv: Sequence[str] | None = None, noise_flag: bool = False) -> int:
    """The body of the example scripts: run the setups, draw the figures, print the tables.

    Args:
        labels: Setups to run: the paper-start twin and the fitted start of one scene, and
            possibly a noisy variant.
        description: The script's one-line description.
        argv: Command-line arguments (default ``sys.argv[1:]``).
        noise_flag: Offer ``--noise PX``: the pixel noise of the noisy setup (0 skips it).
    """
    parser = example_parser(description)
    if noise_flag:
        parser.add_argument("--noise", type=float, default=0.5,
                            help="pixel noise of the noisy run (default 0.5; 0 skips it)")
    args = parser.parse_args(argv)
    check_args(args)
    setups = [SETUPS[label] for label in labels]
    if noise_flag:
        if args.noise < 0:
            raise SystemExit(f"--noise: must be non-negative, got {args.noise}")
        setups = [dataclasses.replace(s, noise=args.noise) if s.noise else s for s in setups]
        setups = [s for s in setups if s.noise or not s.label.endswith("-noise")]
    runs = [run_setup(s, resolution=args.resolution, iterations=args.iterations,
                      device=args.device) for s in setups]
    figures = scene_figures(runs, args.out_dir)
    print_table(runs)
    fitted = next(e for e in runs if not is_paper_start(e.setup) and not e.setup.noise)
    print()
    print(f"Accuracy of {fitted.setup.label}, inside the constraints' hull:")
    print()
    print(fitted.evaluation.table())
    print()
    print("figures: " + ", ".join(str(f) for f in figures))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = example_parser("Run the paper-reproduction setups, draw every figure and print "
                            "the results table.")
    parser.add_argument("--setups", nargs="+", default=list(SETUPS), choices=list(SETUPS),
                        metavar="SETUP", help=f"setups to run (default: all of {list(SETUPS)})")
    parser.add_argument("--ablation", action="store_true",
                        help="also run each fitted-start setup without reinitialisation and "
                             "with the 'axis' band of DESIGN section 6, and print that table")
    parser.add_argument("--no-figures", action="store_true", help="only print the tables")
    args = parser.parse_args(argv)
    check_args(args)
    runs = []
    for label in args.setups:
        exp = run_setup(label, resolution=args.resolution, iterations=args.iterations,
                        device=args.device)
        print(table_row(exp), file=sys.stderr, flush=True)
        runs.append(exp)
    if not args.no_figures:
        for path in scene_figures(runs, args.out_dir):
            print(f"wrote {path}", file=sys.stderr)
    print_table(runs)
    if args.ablation:
        rows = []
        for label in args.setups:
            if is_paper_start(SETUPS[label]):
                continue
            rows += ablation(label, resolution=args.resolution, iterations=args.iterations,
                             device=args.device)
        print()
        print(ABLATION_HEADER)
        print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
