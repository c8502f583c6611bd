"""Compare a reconstructed mesh with the ground truth.

Distances are measured both ways with exact point-to-triangle queries:

- *accuracy*: from points of the reconstructed mesh to the truth mesh;
- *completeness*: from points of the truth mesh to the reconstructed mesh.

Each side is summarised by its mean, root mean square, 95th percentile and maximum, in world
units and, when the grid spacing ``h`` is given, in voxel widths. The Chamfer distance reported
is the *symmetric mean*, ``(accuracy.mean + completeness.mean) / 2``; the Hausdorff distance is
``max(accuracy.max, completeness.max)``.

As in the paper, the comparison can be restricted to the region the constraints cover:
:func:`hull_region` projects points onto the best-fit plane of the constraints (principal
component analysis) and keeps those that fall inside the 2D convex hull of the projected
constraints.

The normal angle at a specular point ``x`` is the angle between the true unit normal there and
the normal of the face of the reconstructed mesh closest to ``x`` (no smoothing: a kink or a
dimple under the highlight counts in full).

No spatial index beyond :class:`scipy.spatial.cKDTree` is needed: trimesh's proximity and ray
queries require ``rtree``, which warpspec does not depend on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from .errors import InputError
from .geometry import HullRegion, hull_region

__all__ = [
    "CHAMFER_CONVENTION",
    "DistanceStats",
    "Evaluation",
    "HullRegion",
    "closest_point",
    "crop_mesh",
    "evaluate",
    "hull_region",
    "mesh_normals_at",
    "ray_mesh_intersect",
    "truth_region",
]

CHAMFER_CONVENTION = "symmetric mean: (accuracy_mean + completeness_mean) / 2"

# Feature of a triangle that holds the closest point (Ericson, Real-Time Collision Detection,
# section 5.1.5): a vertex, an edge or the face itself.
FEATURE_A, FEATURE_B, FEATURE_AB, FEATURE_C, FEATURE_AC, FEATURE_BC, FEATURE_FACE = range(7)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def closest_point_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Exact closest point of each point ``p[i]`` on the triangle ``(a[i], b[i], c[i])``.

    Args:
        p: Query points, shape ``(N, 3)``.
        a: First vertices, shape ``(N, 3)``.
        b: Second vertices, shape ``(N, 3)``.
        c: Third vertices, shape ``(N, 3)``.

    Returns:
        The closest points ``(N, 3)`` and the feature that holds each of them ``(N,)``: one of
        ``FEATURE_A``, ``FEATURE_B``, ``FEATURE_C`` (a vertex), ``FEATURE_AB``, ``FEATURE_AC``,
        ``FEATURE_BC`` (an edge) or ``FEATURE_FACE``.
    """
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = _dot(ab, ap)
    d2 = _dot(ac, ap)
    bp = p - b
    d3 = _dot(ab, bp)
    d4 = _dot(ac, bp)
    cp = p - c
    d5 = _dot(ab, cp)
    d6 = _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2

    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        out = a + ab * v[:, None] + ac * w[:, None]
        feature = np.full(len(p), FEATURE_FACE, dtype=np.int8)

        # Apply the regions in reverse order of Ericson's tests so that earlier tests win.
        def put(mask: np.ndarray, point: np.ndarray, code: int) -> None:
            np.copyto(out, point, where=mask[:, None])
            feature[mask] = code

        e43 = d4 - d3
        e56 = d5 - d6
        den = e43 + e56
        t = np.where(den != 0, e43 / den, 0.0)
        put((va <= 0) & (e43 >= 0) & (e56 >= 0), b + (c - b) * t[:, None], FEATURE_BC)
        den = d2 - d6
        t = np.where(den != 0, d2 / den, 0.0)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * t[:, None], FEATURE_AC)
        put((d6 >= 0) & (d5 <= d6), c, FEATURE_C)
        den = d1 - d3
        t = np.where(den != 0, d1 / den, 0.0)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * t[:, None], FEATURE_AB)
        put((d3 >= 0) & (d4 <= d3), b, FEATURE_B)
        put((d1 <= 0) & (d2 <= 0), a, FEATURE_A)
    return out, feature


def closest_point(
    mesh: trimesh.Trimesh, points: np.ndarray, *, chunk: int = 20_000
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact closest point on a triangle mesh for each query point.

    Candidate triangles are found with a k-d tree on the triangle centroids and a conservative
    bound (a triangle's distance is at least the distance to its centroid minus its radius), so
    the answer is exact, not sampled.

    Args:
        mesh: The triangle mesh.
        points: Query points, shape ``(N, 3)``.
        chunk: Number of query points processed at once (bounds the memory use).

    Returns:
        ``(closest, distance, face, feature)``: the closest points ``(N, 3)``, their distances
        ``(N,)``, the index of the triangle that holds each ``(N,)`` and the feature of that
        triangle (see :func:`closest_point_on_triangles`).

    Raises:
        InputError: If the mesh has no faces.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces)
    if len(faces) == 0:
        raise InputError("mesh: has no faces, cannot measure distances to it")
    tri = np.asarray(mesh.vertices, dtype=np.float64)[faces]
    centroid = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centroid[:, None, :], axis=2).max(axis=1)
    rmax = float(radius.max())
    tree = cKDTree(centroid)
    nf = len(faces)

    def exact(q: np.ndarray, fi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cp, feat = closest_point_on_triangles(q, tri[fi, 0], tri[fi, 1], tri[fi, 2])
        return cp, feat, np.linalg.norm(cp - q, axis=1)

    n = len(points)
    closest = np.empty((n, 3))
    distance = np.full(n, np.inf)
    face = np.zeros(n, dtype=np.int64)
    feature = np.zeros(n, dtype=np.int8)
    for start in range(0, n, chunk):
        pending = np.arange(start, min(start + chunk, n))
        k = min(16, nf)
        while len(pending):
            q = points[pending]
            dc, idx = tree.query(q, k=k, workers=-1)
            dc = np.asarray(dc).reshape(len(q), k)
            idx = np.asarray(idx).reshape(len(q), k)
            # Upper bound from the triangle of the nearest centroid ...
            cp0, feat0, best = exact(q, idx[:, 0])
            bcp, bfeat, bface = cp0, feat0, idx[:, 0].copy()
            # ... then every other candidate whose lower bound |q - centroid| - radius beats it.
            lower = dc - radius[idx]
            qi, j = np.nonzero(lower[:, 1:] < best[:, None])
            j = j + 1
            if len(qi):
                fi = idx[qi, j]
                cp, feat, d = exact(q[qi], fi)
                order = np.lexsort((d, qi))
                first = np.ones(len(order), dtype=bool)
                first[1:] = qi[order][1:] != qi[order][:-1]
                sel = order[first]
                better = d[sel] < best[qi[sel]]
                r, sel = qi[sel][better], sel[better]
                best[r], bcp[r], bfeat[r], bface[r] = d[sel], cp[sel], feat[sel], fi[sel]
            # A triangle whose centroid is not among the k nearest is at least
            # dc[:, -1] - rmax away: the answer is final when that exceeds the best distance.
            done = (k == nf) | (dc[:, -1] - rmax > best)
            out = pending[done]
            closest[out] = bcp[done]
            distance[out] = best[done]
            face[out] = bface[done]
            feature[out] = bfeat[done]
            pending = pending[~done]
            k = min(4 * k, nf)
    return closest, distance, face, feature


def crop_mesh(mesh: trimesh.Trimesh, region: HullRegion) -> trimesh.Trimesh:
    """Keep the triangles whose three vertices lie in ``region``.

    Args:
        mesh: The mesh to crop.
        region: The region, from :func:`hull_region`.

    Returns:
        A new mesh with the kept triangles (unused vertices removed).
    """
    inside = region.contains(mesh.vertices)
    keep = inside[np.asarray(mesh.faces)].all(axis=1)
    out = trimesh.Trimesh(
        vertices=np.asarray(mesh.vertices).copy(),
        faces=np.asarray(mesh.faces)[keep],
        process=False,
    )
    out.remove_unreferenced_vertices()
    return out


@dataclass(frozen=True)
class DistanceStats:
    """Summary of a set of distances.

    Attributes:
        mean: Mean distance.
        rms: Root mean square distance.
        p95: 95th percentile.
        max: Largest distance.
        count: Number of points measured.
    """

    mean: float
    rms: float
    p95: float
    max: float
    count: int

    @classmethod
    def of(cls, d: np.ndarray) -> DistanceStats:
        """Summarise the distances ``d`` (an empty set gives NaN statistics)."""
        d = np.asarray(d, dtype=np.float64).reshape(-1)
        if len(d) == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, 0)
        return cls(
            mean=float(d.mean()),
            rms=float(np.sqrt(np.mean(d * d))),
            p95=float(np.percentile(d, 95)),
            max=float(d.max()),
            count=len(d),
        )

    def scaled(self, factor: float) -> dict[str, float]:
        """The four statistics divided by ``factor`` (e.g. the grid spacing)."""
        return {k: getattr(self, k) / factor for k in ("mean", "rms", "p95", "max")}

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready dictionary."""
        return {"mean": self.mean, "rms": self.rms, "p95": self.p95, "max": self.max,
                "count": self.count}


@dataclass(frozen=True)
class Evaluation:
    """Result of :func:`evaluate`.

    Attributes:
        accuracy: Distances from the reconstructed mesh to the truth.
        completeness: Distances from the truth to the reconstructed mesh.
        spacing: Grid spacing ``h`` for values in voxel widths, or ``None``.
        cropped: Whether the samples were restricted to a region.
        normal_angle_mean: Mean angle in degrees between the mesh normal and the true normal at
            the true specular points, or ``None`` when no points were given.
        normal_angle_max: Largest such angle in degrees, or ``None``.
        normal_angles: The individual angles in degrees, or ``None``.
    """

    accuracy: DistanceStats
    completeness: DistanceStats
    spacing: float | None = None
    cropped: bool = False
    normal_angle_mean: float | None = None
    normal_angle_max: float | None = None
    normal_angles: np.ndarray | None = None

    @property
    def chamfer(self) -> float:
        """Chamfer distance, symmetric mean: ``(accuracy.mean + completeness.mean) / 2``."""
        return 0.5 * (self.accuracy.mean + self.completeness.mean)

    @property
    def hausdorff(self) -> float:
        """Hausdorff distance: ``max(accuracy.max, completeness.max)``."""
        return max(self.accuracy.max, self.completeness.max)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (world units, plus voxel widths when ``spacing`` is set)."""
        out: dict = {
            "accuracy": self.accuracy.to_dict(),
            "completeness": self.completeness.to_dict(),
            "chamfer": self.chamfer,
            "chamfer_convention": CHAMFER_CONVENTION,
            "hausdorff": self.hausdorff,
            "spacing": self.spacing,
            "cropped": self.cropped,
        }
        if self.spacing:
            out["accuracy_voxels"] = self.accuracy.scaled(self.spacing)
            out["completeness_voxels"] = self.completeness.scaled(self.spacing)
            out["chamfer_voxels"] = self.chamfer / self.spacing
            out["hausdorff_voxels"] = self.hausdorff / self.spacing
        if self.normal_angles is not None:
            out["normal_angle_deg"] = {
                "mean": self.normal_angle_mean,
                "max": self.normal_angle_max,
                "count": len(self.normal_angles),
            }
        return out

    def table(self) -> str:
        """A markdown table of the measures."""
        h = self.spacing
        unit = " | mean (h) | rms (h) | p95 (h) | max (h)" if h else ""
        rows = [
            "| measure | mean | rms | p95 | max | points" + unit + " |",
            "|---|---|---|---|---|---" + ("|---" * 4 if h else "") + "|",
        ]
        for name, s in (("accuracy (mesh to truth)", self.accuracy),
                        ("completeness (truth to mesh)", self.completeness)):
            row = f"| {name} | {s.mean:.4g} | {s.rms:.4g} | {s.p95:.4g} | {s.max:.4g} | {s.count}"
            if h:
                v = s.scaled(h)
                row += f" | {v['mean']:.4g} | {v['rms']:.4g} | {v['p95']:.4g} | {v['max']:.4g}"
            rows.append(row + " |")
        chamfer = f"{self.chamfer:.4g}" + (f" ({self.chamfer / h:.4g} h)" if h else "")
        hausdorff = f"{self.hausdorff:.4g}" + (f" ({self.hausdorff / h:.4g} h)" if h else "")
        lines = [
            *rows,
            "",
            f"Chamfer ({CHAMFER_CONVENTION}): {chamfer}",
            f"Hausdorff (max of both maxima): {hausdorff}",
            f"Cropped to the constraint hull: {'yes' if self.cropped else 'no'}",
        ]
        if self.normal_angles is not None:
            mean, top = self.normal_angle_mean, self.normal_angle_max
            if mean is None or top is None or not (math.isfinite(mean) and math.isfinite(top)):
                lines.append("Normal angle at the true specular points: not measured (no true "
                             "specular point with a defined normal: no ray meets the truth, "
                             "or the faces there are degenerate)")
            else:
                lines.append(
                    f"Normal angle at the true specular points: mean {mean:.4g} deg, "
                    f"max {top:.4g} deg ({len(self.normal_angles)} points)"
                )
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()


def _surface_samples(mesh: trimesh.Trimesh, count: int, seed: int) -> np.ndarray:
    samples, _ = trimesh.sample.sample_surface(mesh, count, seed=seed)
    return np.concatenate([np.asarray(samples, dtype=np.float64),
                           np.asarray(mesh.vertices, dtype=np.float64)])


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between rows of ``a`` and ``b`` (accurate near 0 and 180)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), _dot(a, b)))


def evaluate(
    mesh: trimesh.Trimesh,
    truth: trimesh.Trimesh,
    *,
    spacing: float | None = None,
    region: HullRegion | np.ndarray | None = None,
    specular_points: np.ndarray | None = None,
    true_normals: np.ndarray | None = None,
    samples: int = 20_000,
    seed: int = 0,
) -> Evaluation:
    """Measure a reconstructed mesh against the truth.

    Each mesh is sampled uniformly by area (``samples`` points, seeded) plus its vertices, and
    each sample's distance to the other mesh is found exactly (closest point on the triangles),
    so the truth against itself measures 0 up to rounding.

    - accuracy: distances from the samples of ``mesh`` to ``truth``;
    - completeness: distances from the samples of ``truth`` to ``mesh``;
    - Chamfer: the symmetric mean, ``(accuracy.mean + completeness.mean) / 2``
      (:data:`CHAMFER_CONVENTION`); Hausdorff: the larger of the two maxima.

    Args:
        mesh: The reconstructed mesh.
        truth: The ground-truth mesh.
        spacing: Grid spacing ``h``; when given, the values are also reported in voxel widths.
        region: Restrict both sample sets to this region: a :class:`HullRegion` or an array of
            constraint points from which :func:`hull_region` builds one.
        specular_points: True specular points ``(M, 3)``; when given, the angle between the
            normal of the closest face of ``mesh`` and the true normal is measured there.
        true_normals: True unit normals ``(M, 3)`` at ``specular_points``; by default the normals
            of the closest faces of ``truth``.
        samples: Number of area-uniform samples per mesh (vertices come on top).
        seed: Seed of the sampling.

    Returns:
        The measures.

    Raises:
        InputError: If a mesh is empty, the region keeps no sample, or the normals do not match
            the points.
    """
    for label, m in (("mesh", mesh), ("truth", truth)):
        if len(m.faces) == 0:
            raise InputError(f"{label}: has no faces, nothing to evaluate")
    if region is not None and not isinstance(region, HullRegion):
        region = hull_region(np.asarray(region, dtype=np.float64))

    pm = _surface_samples(mesh, samples, seed)
    pt = _surface_samples(truth, samples, seed + 1)
    if region is not None:
        pm = pm[region.contains(pm)]
        pt = pt[region.contains(pt)]
        if len(pm) == 0 or len(pt) == 0:
            raise InputError(
                f"region: keeps {len(pm)} mesh and {len(pt)} truth samples; needs some of both"
            )
    _, accuracy, _, _ = closest_point(truth, pm)
    _, completeness, _, _ = closest_point(mesh, pt)

    angles = None
    if specular_points is not None:
        sp = np.asarray(specular_points, dtype=np.float64).reshape(-1, 3)
        if true_normals is None:
            _, _, tface, _ = closest_point(truth, sp)
            tn = np.asarray(truth.face_normals)[tface]
        else:
            tn = np.asarray(true_normals, dtype=np.float64).reshape(-1, 3)
            if tn.shape != sp.shape:
                raise InputError(
                    f"true_normals: shape {tn.shape} does not match specular_points {sp.shape}"
                )
        if len(sp):
            _, _, face, _ = closest_point(mesh, sp)
            with np.errstate(all="ignore"):
                angles = _angle_deg(np.asarray(mesh.face_normals)[face], tn)
            angles = angles[np.isfinite(angles)]  # degenerate faces have no normal
        else:
            angles = np.zeros(0)

    return Evaluation(
        accuracy=DistanceStats.of(accuracy),
        completeness=DistanceStats.of(completeness),
        spacing=float(spacing) if spacing else None,
        cropped=region is not None,
        normal_angle_mean=float(angles.mean()) if angles is not None and len(angles) else None,
        normal_angle_max=float(angles.max()) if angles is not None and len(angles) else None,
        normal_angles=angles,
    )


def mesh_normals_at(
    mesh: trimesh.Trimesh, points: np.ndarray, *, mode: str = "face"
) -> np.ndarray:
    """Unit normals of ``mesh`` at the points of it closest to ``points``.

    Args:
        mesh: The mesh.
        points: Query points ``(N, 3)``.
        mode: ``"face"``: the normal of the closest face (what :func:`evaluate` reports);
            ``"vertex"``: the vertex normals (trimesh's, averaged over the faces around each
            vertex) interpolated barycentrically at the closest point, as a shaded render shows
            the surface.

    Returns:
        Unit normals ``(N, 3)``.

    Raises:
        InputError: If ``mode`` is unknown or the mesh has no faces.
    """
    if mode not in ("face", "vertex"):
        raise InputError(f"mode: expected 'face' or 'vertex', got {mode!r}")
    cp, _, face, _ = closest_point(mesh, points)
    if mode == "face":
        return np.asarray(mesh.face_normals, dtype=np.float64)[face]
    tri = np.asarray(mesh.triangles, dtype=np.float64)[face]
    bary = trimesh.triangles.points_to_barycentric(tri, cp)
    vn = np.asarray(mesh.vertex_normals, dtype=np.float64)[np.asarray(mesh.faces)[face]]
    n = np.einsum("ij,ijk->ik", bary, vn)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def ray_mesh_intersect(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray, *, chunk: int = 4_000_000
) -> tuple[np.ndarray, np.ndarray]:
    """First intersection of each ray with a triangle mesh (Moller-Trumbore, every triangle).

    Brute force over the triangles, in chunks of ``chunk`` ray-triangle pairs: exact, needs no
    spatial index, and fast enough for the few dozen rays of a scene.

    Args:
        mesh: The mesh (either side of a triangle counts).
        origins: Ray origins ``(M, 3)``.
        directions: Ray directions ``(M, 3)`` (need not be unit).
        chunk: Ray-triangle pairs tested at once (bounds the memory use).

    Returns:
        ``(points, faces)``: the first hit of each ray in front of its origin ``(M, 3)`` (NaN
        when the ray misses) and the index of the face it hits ``(M,)`` (-1 on a miss).
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    m, f = len(o), len(tri)
    points = np.full((m, 3), np.nan)
    faces = np.full(m, -1, dtype=np.int64)
    if f == 0 or m == 0:
        return points, faces
    a = tri[:, 0]
    e1 = tri[:, 1] - a
    e2 = tri[:, 2] - a
    scale = float(np.abs(tri).max()) or 1.0
    per = max(1, chunk // f)
    for start in range(0, m, per):
        oo = o[start:start + per, None, :]
        dd = d[start:start + per, None, :]
        p = np.cross(dd, e2[None])
        det = np.einsum("rfk,fk->rf", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = oo - a[None]
            u = np.einsum("rfk,rfk->rf", s, p) * inv
            q = np.cross(s, e1[None])
            v = np.einsum("rfk,rfk->rf", np.broadcast_to(dd, q.shape), q) * inv
            t = np.einsum("rfk,fk->rf", q, e2) * inv
            tol = 1e-12
            ok = ((np.abs(det) > 1e-300) & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol)
                  & (t > 1e-12 * scale))
        t = np.where(ok, t, np.inf)
        best = np.argmin(t, axis=1)
        tb = t[np.arange(len(t)), best]
        hit = np.isfinite(tb)
        rows = np.arange(start, start + len(t))[hit]
        points[rows] = o[rows] + tb[hit, None] * d[rows]
        faces[rows] = best[hit]
    return points, faces


def truth_region(
    specular_points: np.ndarray, points: np.ndarray, *, margin: float = 0.0
) -> HullRegion:
    """The region the constraints cover, from the true geometry.

    The hull (see :func:`hull_region`) of the true specular points and the point constraints:
    the crop the paper shows, taken from the truth rather than from the reconstruction, so that
    every reconstruction of a scene is scored over the same region.

    Args:
        specular_points: True specular points ``(M, 3)`` (NaN rows are ignored).
        points: Point constraints ``(S, 3)``.
        margin: Grow the hull by this distance in world units.

    Raises:
        InputError: If the points span no 2D hull.
    """
    sp = np.asarray(specular_points, dtype=np.float64).reshape(-1, 3)
    sp = sp[np.all(np.isfinite(sp), axis=1)]
    return hull_region(np.vstack([sp, np.asarray(points, dtype=np.float64).reshape(-1, 3)]),
                       margin=margin)
