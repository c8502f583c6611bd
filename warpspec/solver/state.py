"""What a reconstruction hands back, and the level-set files it reads and writes.

:class:`Result` holds the mesh, the level set, its grid, the measures and the verdict;
:func:`save_state` and :func:`load_state` write and read a level set with its grid (NPZ),
checking a file's size and declared shapes before anything is expanded.
"""

from __future__ import annotations

import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._atomic import atomic_write, check_size
from ..errors import InputError
from ..grid import MAX_NODES, Grid
from ..mesh import triangulate, write_ply
from ..scene import Scene, rays_meet_box
from ..verdict import Verdict, assess

if TYPE_CHECKING:
    import trimesh

__all__ = ["MAX_STATE_BYTES", "Result", "check_covers", "free_host_memory", "load_state",
           "save_state", "write_state"]


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
        normals = rays = None
        if self.hits is not None and scene.num_specularities:
            hits = np.asarray(self.hits, dtype=np.float64)
            ok = np.all(np.isfinite(hits), axis=1)
            rays = scene.rays()
            origins, dirs = rays
            normals = scene.normals(np.where(ok[:, None], hits, origins + dirs))
            normals[~ok] = np.nan
        self.verdict, self.support = assess(
            phi=self.phi, grid=self.grid, vertices=self.vertices, hits=self.hits,
            demanded_normals=normals, points=scene.points, camera_rays=rays)
        return self.verdict

    def save_phi(self, path: str | os.PathLike) -> None:
        """Save the level set and its grid to an ``.npz`` file (:meth:`load` reads it)."""
        save_state(path, self.phi, self.grid)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Result:
        """A result from a level set saved by :meth:`save_phi`, its zero set triangulated.

        It has no history, hits or verdict; hand it to ``Reconstructor(scene, phi0=...)`` to
        continue from it.

        Raises:
            InputError: If the file is missing, too large or not a saved level set.
        """
        phi, grid = load_state(path)
        vertices, faces = triangulate(phi, grid)
        return cls(vertices=vertices, faces=faces, phi=phi, grid=grid)


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


def free_host_memory() -> int | None:
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
            free = free_host_memory()
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


def check_holds(scene: Scene, grid: Grid, field: str) -> None:
    """Refuse a grid that holds nothing to reconstruct: no point inside, no ray entering it.

    Args:
        scene: The scene.
        grid: The grid (from the scene's domain, or given).
        field: What names the grid in messages (``domain``, ``grid``).

    Raises:
        InputError: If none of the scene's points lies in the grid and none of its specular
            rays enters it.
    """
    lo, hi = grid.origin, grid.upper
    inside = bool(np.any(np.all((scene.points >= lo) & (scene.points <= hi), axis=1)))
    enters = bool(scene.num_specularities) and bool(rays_meet_box(*scene.rays(), lo, hi).any())
    if not (inside or enters):
        raise InputError(
            f"{field}: the box min={np.round(lo, 6).tolist()} max={np.round(hi, 6).tolist()} "
            f"holds none of the scene's {scene.num_points} points and none of its "
            f"{scene.num_specularities} specular rays enters it; give a domain around the "
            "object (or none, to derive it from the points)")


def check_covers(scene: Scene, grid: Grid, field: str) -> None:
    """Refuse a level set handed in whose grid does not hold the scene's constraints.

    Args:
        scene: The scene.
        grid: The level set's grid.
        field: What names the level set in messages (``resume: 'phi.npz'``, ``phi0``).

    Raises:
        InputError: If a point lies outside the grid, or no specular ray enters it.
    """
    lo, hi, h = grid.origin, grid.upper, grid.spacing
    box = f"min={np.round(lo, 6).tolist()} max={np.round(hi, 6).tolist()}"
    outside = int(np.sum(np.any((scene.points < lo - h) | (scene.points > hi + h), axis=1)))
    if outside:
        raise InputError(f"{field} was saved on a grid ({box}) that leaves "
                         f"{outside} of the scene's {scene.num_points} points outside; resume "
                         "only with the scene it was saved from")
    if scene.num_specularities:
        origins, dirs = scene.rays()
        if not rays_meet_box(origins, dirs, lo, hi).any():
            raise InputError(f"{field} was saved on a grid ({box}) that no "
                             "specular ray of the scene enters; resume only with the scene it "
                             "was saved from")
