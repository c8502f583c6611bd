"""A surface of revolution fitted to the normal lines of highlights: bottles, vases, cans.

Every normal line of a surface of revolution meets its axis. With a flash at the camera a
highlight's ray is a normal line (:func:`fit_revolution`); under another light each ray has one
point whose normal line meets a given axis, and the axis is the one that makes those points one
smooth profile (:func:`fit_revolution_lit`). Rotational
symmetry makes sparse data go far: each point gives the profile's radius at its height all the
way round, and each normal line the profile's slope where it meets the profile. The fit
(docs/DESIGN.md section 7):

1. the axis: the line the normal lines pass nearest (the torus' search over 2,000 directions),
   refined by robust least squares (scipy's ``soft_l1`` loss); a line that passes farther than
   :data:`AXIS_VOXELS` voxels from it belongs to no surface of revolution about this axis (a
   false highlight) and is left out;
2. the profile ``r(h)``: radii on knots a twentieth of a voxel apart along the axis over the
   domain (:data:`KNOT_VOXELS`),
   fitted by least squares to the points' radii (averaged over half a voxel of height,
   :func:`_point_rows`) and to the lines' slopes where each line
   first meets the current profile, with the third-order energy ``|r'''|^2`` as smoothness
   (its null space holds every quadratic profile, so a cone or a paraboloid costs nothing),
   measured along the profile by flash (:func:`_arc_length_weights`), and a flatness that
   puts a shoulder's drop where no datum holds the profile flat (:data:`FLATNESS`);
   lines are met again and the profile refitted :data:`PROFILE_ROUNDS` times, each slope
   weighed by Tukey's biweight of its angle; by flash, a profile fitted from the cylinder
   that shows its cameras highlights they did not see is fitted again from drops between the
   points (:func:`_profile_start`), and points that the profile fitted without each one
   misses (:func:`_points_disagree`) weigh as noisy and the profile is refitted.

The implicit start takes the surface when the quadric and the torus do not meet the normals and
it does, as it would take a quadric.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .geometry import angle_deg, miss_deg, plane_frame
from .normal_lines import best_axis, first_crossing
from .quadric import NOISY_POINT_WEIGHT as NOISY_QUADRIC_POINT_WEIGHT
from .quadric import biweight, robust_sigma

__all__ = ["SurfaceOfRevolution", "fit_revolution", "fit_revolution_lit"]

MIN_RAYS = 12
"""Fewest normal lines near one axis a surface of revolution is fitted to."""
AXIS_VOXELS = 0.5
"""A normal line passing farther than this many voxels from the axis is left out."""
AXIS_SHARE = 0.5
"""At least this share of the normal lines must pass the axis within AXIS_VOXELS."""
AXIS_SIGMAS = 6.0
"""Once the axis is refined, a line is kept within this many robust deviations of the kept
lines' distances from it (between AXIS_FLOOR and AXIS_VOXELS voxels)."""
AXIS_FLOOR = 0.05
KNOT_VOXELS = 0.05
"""Spacing of the profile's knots along the axis, in voxels. A ring of cameras at one height
sees a bottle's shoulder in a band a fraction of a voxel high; the spread of the slopes its
highlights ask there is the profile's curvature, which the third-order energy carries across
the unseen steep middle of the shoulder. The slope is constant across a knot's cell, so on
knots half a voxel apart that band held one or two slopes, the curvature was lost, and the
shoulder came out too gentle and the neck 2-3 voxels fat. Truth->mesh, bottle by flash, seeds
0-8: worst 0.540 h at 0.5, 0.324 at 0.1, 0.305 at 0.05 (0.5 px of noise: 0.533, 0.374, 0.362);
under lamps, seeds 0-5, every variant: worst 0.265 h at 0.5, 0.221 at 0.05, and at a quarter
false at most 0.114 h from the clean result at 0.5, 0.074 at 0.05."""
PROFILE_ROUNDS = 20
"""Intersect-and-refit rounds of the profile."""
PROFILE_SMOOTHNESS = 1e-6
"""Weight of the third-order energy of the profile, lengths in units of the domain's size."""
POINT_WEIGHT = 20.0
"""Weight of a point's radius error in voxels, against 1 for a unit error of a line's slope,
under lamps (the axis' cost and the final profile)."""
NOISY_POINT_WEIGHT = float(np.sqrt(NOISY_QUADRIC_POINT_WEIGHT))
"""The same weight for points that carry noise, as the quadric weighs them
(:data:`warpspec.quadric.NOISY_POINT_WEIGHT`): a point 0.55 voxel off weighs as much as a
slope a degree off. Under lamps each ray's hit gives the profile's radius, so the points need
not fix the depth. See :meth:`warpspec.implicit.ImplicitStart._noisy_points_revolution` for
when it is used."""
PROFILE_POINT_WEIGHT = 0.5
"""The same weight in the profile's fit to flash-lit lines. Two points at nearly one height
whose radii differ by a fraction of a voxel (an axis a tenth of a degree off puts them so) ask
a slope between them; at 20 the fit gave it, and the third-order energy carried it on as a
wave 3-4 voxels deep over the body (bottle seed 7, 0.5 px of noise: truth->mesh 0.95 h, 0.50
at 0.5). Points off the surface by their own noise pull less too: six random points 0.3 voxel
(rms) off, seeds 0-5 but 3 (which falls to the grid fit either way), 0.20-0.52 h (0.20-1.26 at
2, with the straight ends of before).
The catalogue's exact points are still met within 0.02 voxel."""
NOISY_PROFILE_SIZE = 0.3 / 64.0
"""By flash the profile is refitted with the points weighed :data:`NOISY_PROFILE_POINT_WEIGHT`
when the profile fitted without each point misses it by a median of more than this share of the
domain's largest side (:func:`_points_disagree`; 0.3 voxel at resolution 64, whatever the grid,
as :data:`warpspec.implicit.QUADRIC_POINT_SIZE`). By flash only the points fix the depth, and
held at :data:`PROFILE_POINT_WEIGHT` the profile follows each one: points that carry noise of
half a voxel per axis left bottles 0.20-0.94 voxel from the truth (the truth's mean distance
from the fitted profile, seeds 0-5), at a voxel 0.47-1.90; a body whose one point lay 1.3 voxel
in was drawn 1.2 voxel thin over the rays' band, and two points half a voxel apart in height
and a voxel apart in radius bent the bottom 3 voxels out. Over seeds 0-11 the medians were
0.01-0.05 voxel with exact points (clean or a quarter false), 0.02-0.23 with 1 px of noise on
the highlights, 0.13-0.57 with points a quarter of a voxel off, 0.28-0.79 at half a voxel and
0.40-1.87 at a voxel; the profiles taken 0.10-0.37, 0.11-0.49 and 0.16-0.98 voxel from the
truth."""
NOISY_PROFILE_POINTS = 3
"""Fewest points whose disagreement is judged: fewer are held as they are."""
NOISY_PROFILE_POINT_WEIGHT = 0.05
"""The points' weight by flash when they disagree: a point a voxel off weighs as a slope 0.05 (3
degrees) off, and the rays' slopes shape the profile while the points, all together, fix its
depth. Bottle by flash, seeds 0-5, points half a voxel off per axis: 0.12-0.42 voxel from the
truth (0.16-0.59 at 0.15, 0.24-0.52 at 0.03, where the flatness takes over where no ray is:
0.17-0.20 with exact points at 0.05, 0.36-0.37 at 0.03), a voxel off: 0.17-0.87."""
FLATNESS = 10.0
"""Weight of the profile's flatness, ``FLATNESS * FLAT_SLOPE^2 * log(1 + (r' / FLAT_SLOPE)^2)``
integrated along the axis (lengths in units of the domain's size), against 1 for a unit error
of a line's slope, between the lowest and the highest radius datum (:func:`_flatness_weights`).
Bottles, vases and cans are near cylinders joined by short shoulders, and the highlights see a
shoulder only in bands, at the slopes a ring of cameras can see: how the profile drops between
a band and the next point, the data do not say. The third-order energy alone spreads the drop
over the whole gap, so the neck came out fat above the shoulder, thinning slowly up to the
neck's point (bottle by flash, seeds 0-29 and 300-302: 0.09-0.32 h; with a shoulder 0.55 as
wide, seeds 0-2, the neck 3.4-3.7 voxels fat at most). The logarithm costs a drop the less the
shorter and steeper it is, and a flat stretch almost nothing, so the drop goes where no datum
holds the profile flat: 0.04-0.23 h, and that neck within 0.46 voxel. Not being a square, it
may settle in more than one minimum (:func:`_profile_start`). A shoulder 1.6 times as wide as the
catalogue's is drawn somewhat sharper than it is (seeds 0-11: 0.03-0.06 h before, 0.11-0.19
after). It is minimised by reweighing each round (``FLATNESS * FLAT_SLOPE^2 / (FLAT_SLOPE^2 +
r'^2)`` on ``r'^2``, from the round before)."""
FLAT_SLOPE = 0.05
"""The slope below which the flatness costs as a square and above which as a logarithm."""
UNSEEN_VOXELS = 3.0
"""By flash a camera sees a highlight wherever the surface's normal points at it: a highlight a
profile shows one of its cameras counts as seen when one of that camera's rays passes within
this many voxels of it (:func:`_unseen_highlights`)."""
UNSEEN_SHARE = 0.5
"""A profile started otherwise than from the cylinder is taken only when it shows at most this
share of the highlights unseen that the cylinder's shows (:func:`_profile_start`)."""
LEDGE_SLOPE = 10.0
"""A profile taken from another start has no ledge: it drops at most :data:`LEDGE_SIZE` of
radius between its points where it is steeper than this (``|r'|``, within 6 degrees of
level). A ledge no camera sees costs the flatness almost nothing, and it hides highlights a
camera missed (a bottle seen from one ring of cameras, seed 5: a profile with a ledge 9.7
voxels deep showed 3 highlights unseen against the truth's 20, and lay 0.87 voxel off, 0.06
from the cylinder). The ledges of the starts tried on the catalogue's bottles drop 7-12
voxels; the profiles near the truth, 0-3.4 (a fat bottle's sharp shoulder, seed 4)."""
LEDGE_SIZE = 5.0 / 64.0
"""Deepest drop at slopes over :data:`LEDGE_SLOPE` a profile from another start has, as a share
of the domain's largest side (5 voxels at resolution 64, whatever the grid)."""
START_MET_DEG = 3.0
"""Other starts are tried only where the profile fitted from the cylinder meets at least
:data:`START_MET_SHARE` of its lines within this many degrees: one that misses more is no
surface of revolution whatever its start (the blob seen all around tries one about its lines
before its grid fit, and the other starts cost it 3.3 s)..."""
START_MET_SHARE = 0.5
"""...this share."""
SHOULDER_CENTRES = (0.2, 0.35, 0.5, 0.65, 0.8)
"""Where, as shares of the gap between two points of different radii, the profile's other
starts by flash put the drop between them (:func:`_shoulder_starts`)..."""
SHOULDER_WIDTHS = (0.1, 0.25)
"""...and over what share of that gap it falls."""
SHOULDER_RADII_VOXELS = 4.0
"""Least difference of radius (voxels) between two points, neighbours in height, across
which those starts are tried: a bottle's body and its neck (11 voxels on the catalogue's), not
the points' own noise (a voxel per axis put neighbours of the bottle seed 2 2.5-3.1 voxels
apart, and the starts across them only overflowed)."""
SHOULDER_GAPS = 2
"""Most gaps between points tried so, those with the largest differences of radius first."""
SLOPE_LIMIT_DEG = 20.0
"""Tukey limit of a line's slope weight (the angle between its direction and the normal)."""
LEAVE_OUT_DEG = 15.0
"""Largest out-of-sample miss (degrees) of a flash-lit line the profile keeps: the angle
between its normal and that of the profile fitted without it, at its height. A false
highlight whose line passed near the axis asked a slope 50 degrees off between the shoulder's
band of highlights and the neck's, and the profile followed it (bottle seed 11, a quarter
false: 1.2 h off, 0.24 without it). Over seeds 0-11 of the bottle by flash (clean, 0.5 px of
noise, a tenth and a quarter false, one ring of cameras or two) the true lines are missed by
at most 2.5 degrees out of sample, the false ones kept by 21-51."""
LEAVE_OUT_PASSES = 8
"""Most lines the profile fit leaves out (one per pass, refitted each time)."""
LIT_STARTS = 6
"""Under other lights: axis directions tried around the first guess, besides the guess..."""
LIT_TILT_DEG = 6.0
"""...each this far from it."""
LIT_SCALE = 0.3
"""Scale of the Cauchy loss on the profile fit's residuals (radii in voxels, slopes in units
of the normal) when the axis is refined. At 0.1 pixel noise of 0.5 moved the axis 0.4 degrees
(bottle-lamps seed 2: 0.38 h from the clean result, now 0.25); at 0.6 a quarter of false
highlights won on every seed tried."""
LIT_STAGES = ((2.0, 1e-4), (1.0, 1e-6), (0.5, 1e-6))
"""Knot spacing (voxels) and smoothness of each stage of an axis' refinement: a stiff profile
on coarse knots first (a smoother cost), then a supple one."""
LIT_NO_HIT = 10.0
"""Residual of a ray that has no hit for an axis (its normal line cannot meet it)."""
LIT_ROUNDS = 4
"""Reweighing rounds of the final profile under other lights."""
LIT_LIMIT_VOXELS = 2.0
"""Tukey limit of a ray's radius miss (voxels) in the final profile under other lights."""
LIT_HIT_WEIGHT = 0.2
"""Weight of a ray's hit (where its normal line meets the axis) as a radius datum in voxels,
against 1 for a unit error of a slope, in the profile refitted under other lights as by flash
(each ray traced to the profile, its normal asked there). Without it that refit holds radii
only at the points, and between them slopes alone: bottle-lamps seed 21 with 0.5 px of noise,
from the true axis, bulged 2.3 voxels on average over the body between points at heights
-0.35 and 0.18, where the rays' hits lay within 0.35 voxel of the truth (0.96 h end to end
from the start's shape, now 0.19); at 0.05 the bulge was 0.6-2.0 voxels; at 1 the profile is
the hits' own, which move with the noise of each ray's direction. Only the hits of the rays
whose normals the refit without them meets within 3 degrees are held (a false highlight
whose hit lies near the profile, else, bent it to meet its normal too), and the profile held
so is taken unless the one without them meets more normals within 3 or within 10 degrees:
from an axis a few degrees off the hits hold it where no surface about that axis lies."""


class ProfileFit(NamedTuple):
    """A profile fit's radii, its lines' and points' out-of-sample misses, and its cost."""

    radii: np.ndarray
    misses: np.ndarray | None
    point_misses: np.ndarray | None
    energy: float


@dataclass(frozen=True)
class SurfaceOfRevolution:
    """A surface of revolution: a point and unit direction of its axis, and its profile.

    Attributes:
        base: The axis' point at height 0 ``(3,)``.
        axis: Unit axis direction ``(3,)``.
        heights: Heights of the profile's knots along the axis (evenly spaced, increasing).
        radii: The profile's radius at each knot (``>= 0``).
    """

    base: np.ndarray
    axis: np.ndarray
    heights: np.ndarray
    radii: np.ndarray

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height, distance from the axis and the unit radial direction of points ``(N, 3)``."""
        v = np.asarray(x, dtype=np.float64).reshape(-1, 3) - self.base
        h = v @ self.axis
        radial = v - h[:, None] * self.axis
        rho = np.linalg.norm(radial, axis=1)
        e = radial / np.maximum(rho, 1e-300)[:, None]
        return h, rho, e

    def slopes(self) -> np.ndarray:
        """``r'`` at each knot (computed once: a ray trace asks for it at every step)."""
        return self._slopes

    @functools.cached_property
    def _slopes(self) -> np.ndarray:
        return np.gradient(self.radii, self.heights)

    def value(self, x: np.ndarray) -> np.ndarray:
        """First-order signed distance ``(rho - r(h)) / sqrt(1 + r'(h)^2)`` (negative inside)."""
        h, rho, _ = self.split(x)
        r = np.interp(h, self.heights, self.radii)
        s = np.interp(h, self.heights, self.slopes())
        return (rho - r) / np.sqrt(1.0 + s * s)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal of the profile at the points' heights ``(N, 3)``."""
        h, _, e = self.split(x)
        s = np.interp(h, self.heights, self.slopes())
        g = e - s[:, None] * self.axis
        return g / np.linalg.norm(g, axis=1, keepdims=True)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray, *, step: float) -> tuple[np.ndarray, np.ndarray]:
        """First crossing of each ray with the surface in the box ``[lo, hi]``.

        Sphere tracing at half the first-order distance
        (:func:`warpspec.normal_lines.first_crossing`).
        """
        return first_crossing(self.value, origins, dirs, lo, hi, step=step, safety=0.5)


def _line_axis_distance(c: np.ndarray, a: np.ndarray, p: np.ndarray,
                        n: np.ndarray) -> np.ndarray:
    """Distance between each line ``p + s n`` and the axis line ``c + s a``."""
    m = np.cross(n, a)
    length = np.linalg.norm(m, axis=1)
    along = np.linalg.norm(np.cross(p - c, a), axis=1)  # a line parallel to the axis
    with np.errstate(invalid="ignore", divide="ignore"):
        skew = np.abs(np.einsum("ij,ij->i", p - c, m)) / length
    return np.where(length > 1e-9, skew, along)


def _axis_moves(c: np.ndarray, a: np.ndarray, voxel: float
                ) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The axis ``(c, a)`` moved by four numbers, for least squares in any unit.

    The first two move its point across it, in voxels; the last two tilt its direction.
    """
    u, w = plane_frame(a)[:2]

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        direction = a + x[2] * u + x[3] * w
        return c + voxel * (x[0] * u + x[1] * w), direction / np.linalg.norm(direction)

    return unpack


def _refine_axis(c: np.ndarray, a: np.ndarray, p: np.ndarray, n: np.ndarray,
                 voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Robust least squares of the lines' distances from the axis, in voxels.

    soft_l1 with scale AXIS_VOXELS / 2; the axis' point moves in voxels, so any unit fits alike.
    """
    from scipy.optimize import least_squares

    unpack = _axis_moves(c, a, voxel)
    fit = least_squares(lambda x: _line_axis_distance(*unpack(x), p, n) / voxel, np.zeros(4),
                        loss="soft_l1", f_scale=0.5 * AXIS_VOXELS, max_nfev=200)
    return unpack(fit.x)


def _finite_or_none(fit: Callable) -> Callable:
    """A fit run with numerical warnings silenced; a shape with a profile not finite: ``None``.

    Asked of data that no surface of revolution explains (a blob seen all around), the
    profile's slopes can grow without bound and its banded system turn singular (the
    profile's radii are NaN then): that shape is no answer, and the warnings are no news to
    a user.
    """
    @functools.wraps(fit)
    def quiet(*args, **kwargs):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            out = fit(*args, **kwargs)
        shape = out[0] if isinstance(out, tuple) else out
        if shape is not None and not np.all(np.isfinite(shape.radii)):
            return (None, *out[1:]) if isinstance(out, tuple) else None
        return out

    return quiet


@_finite_or_none
def fit_revolution(starts: np.ndarray, dirs: np.ndarray, points: np.ndarray, *,
                   lo: np.ndarray, hi: np.ndarray, voxel: float, refine: bool = True
                   ) -> tuple[SurfaceOfRevolution | None, np.ndarray]:
    """Fit a surface of revolution to normal lines and surface points.

    Args:
        starts: A point of each normal line outside the surface ``(M, 3)`` (a flash-lit ray's
            camera centre).
        dirs: Unit directions of the lines, inward from ``starts`` ``(M, 3)``.
        points: Surface points ``(P, 3)``.
        lo: The domain's lower corner.
        hi: The domain's upper corner.
        voxel: The grid's spacing.
        refine: Refine the axis by the robust least squares of the lines' distances from it
            (:func:`_refine_axis`); ``False`` keeps the closed-form axis
            (:func:`warpspec.normal_lines.best_axis`), which may be a fraction of a degree
            off yet give a profile that meets more of the lines where few hold it.

    Returns:
        The surface (or ``None`` when fewer than :data:`MIN_RAYS` lines, or less than
        :data:`AXIS_SHARE` of them, pass near one axis, or there is no point) and the mask of
        the lines it was fitted to.
    """
    p = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    none = np.zeros(len(p), dtype=bool)
    if len(p) < MIN_RAYS or len(pts) == 0:
        return None, none
    c, a = best_axis(p, n)
    if c is None:
        return None, none
    if refine:
        c, a = _refine_axis(c, a, p, n, voxel)
    near = _line_axis_distance(c, a, p, n) <= AXIS_VOXELS * voxel
    if near.sum() < MIN_RAYS or near.mean() < AXIS_SHARE:
        return None, near
    for _ in range(2):
        # refit to the lines near the axis, then keep those within a few robust deviations
        if refine:
            c, a = _refine_axis(c, a, p[near], n[near], voxel)
        dist = _line_axis_distance(c, a, p, n)
        spread = AXIS_SIGMAS * robust_sigma(dist[near])
        near = dist <= np.clip(spread, AXIS_FLOOR * voxel, AXIS_VOXELS * voxel)
        if near.sum() < MIN_RAYS:
            return None, near
    heights = _knots(c, a, lo, hi, KNOT_VOXELS * voxel)
    profile = SurfaceOfRevolution(c, a, heights, np.zeros(len(heights)))
    ph, prho, _ = profile.split(pts)
    keep = (ph >= heights[0]) & (ph <= heights[-1])
    if not keep.any():
        return None, near
    scale = float(np.max(np.asarray(hi) - np.asarray(lo)))
    # a line that the profile fitted without it misses by more than LEAVE_OUT_DEG is left
    # out, the worst first, one at a time: a false highlight's line that passes near the axis
    # asks a slope at a height no other datum holds, and the profile follows it
    start = None
    for left_out in range(LEAVE_OUT_PASSES + 1):
        fit = _fit_profile(profile, ph[keep], prho[keep], p[near], n[near], scale=scale,
                           voxel=voxel, radii=start, leave_out=True)
        if left_out == 0:
            start = _profile_start(profile, fit, ph[keep], prho[keep], p[near], n[near],
                                   lo=lo, hi=hi, scale=scale, voxel=voxel)
            if start is not None:
                fit = _fit_profile(profile, ph[keep], prho[keep], p[near], n[near],
                                   scale=scale, voxel=voxel, radii=start, leave_out=True)
        radii, misses, point_misses, _ = fit
        worst = np.where(np.isfinite(misses), misses, -1.0)
        # (a line is left out only where a refit follows: the radii are made without it)
        if (worst.max() <= LEAVE_OUT_DEG or near.sum() <= MIN_RAYS
                or left_out == LEAVE_OUT_PASSES):
            break
        near[np.flatnonzero(near)[int(np.argmax(worst))]] = False
    if _points_disagree(point_misses, scale):
        radii = _fit_profile(profile, ph[keep], prho[keep], p[near], n[near], scale=scale,
                             voxel=voxel, radii=radii,
                             point_weight=NOISY_PROFILE_POINT_WEIGHT)[0]
    return SurfaceOfRevolution(c, a, heights, radii), near


def _profile_start(profile: SurfaceOfRevolution, plain: ProfileFit, ph: np.ndarray,
                   prho: np.ndarray, p: np.ndarray, n: np.ndarray, *, lo: np.ndarray,
                   hi: np.ndarray, scale: float, voxel: float) -> np.ndarray | None:
    """The radii a profile by flash starts from: ``None``, the cylinder, unless that errs.

    ``plain`` is the profile fitted from the cylinder to the points ``(ph, prho)`` and the
    lines ``p + s n``.

    The profile is fitted by rounds of meeting and refitting, and a flatness that is no square
    (:data:`FLATNESS`) has more than one minimum: between a band of highlights on a shoulder
    and a point on the neck, the drop from the body to the neck may lie in the shoulder's
    unseen middle or above the band, and the slopes and the points are met either way. Yet
    the normals of a profile whose drop lies above the band point at the cameras there, where
    none saw a highlight (a bottle with a shoulder half as wide as the catalogue's, seed 3:
    from the cylinder the neck 4.7 voxels fat, 25 highlights foreseen unseen; fitted from the
    truth, none). So when the profile fitted from the cylinder shows
    :func:`_unseen_highlights`, it is fitted again from drops at several heights and widths
    between the points (:func:`_shoulder_starts`), and the start whose profile shows the
    fewest (at most :data:`UNSEEN_SHARE` of the cylinder's), then costs least
    (:func:`_profile_energy`), is taken; never one with a ledge (:data:`LEDGE_SLOPE`), and none
    where the cylinder's profile meets fewer than :data:`START_MET_SHARE` of its lines.
    """
    middle = 0.5 * (profile.heights[1:] + profile.heights[:-1])
    held = (middle >= ph.min()) & (middle <= ph.max())
    step = profile.heights[1] - profile.heights[0]

    def shape(fit: ProfileFit) -> tuple[SurfaceOfRevolution, tuple[int, float]] | None:
        if not np.all(np.isfinite(fit.radii)):
            return None  # a steep start's system may overflow: no profile, no start
        drop = np.abs(np.diff(fit.radii))[held]
        if drop[drop > LEDGE_SLOPE * step].sum() > LEDGE_SIZE * scale:
            return None
        surface = SurfaceOfRevolution(profile.base, profile.axis, profile.heights, fit.radii)
        return surface, (_unseen_highlights(surface, p, n, lo=lo, hi=hi, voxel=voxel),
                         fit.energy)

    cylinder = shape(plain)
    if cylinder is None or cylinder[1][0] == 0:
        return None
    met = _misses(cylinder[0], p, n, -n, lo=lo, hi=hi, voxel=voxel) <= START_MET_DEG
    if np.mean(met) < START_MET_SHARE:
        return None
    best, chosen = cylinder[1], None
    for radii in _shoulder_starts(profile.heights, ph, prho, voxel):
        tried = shape(_fit_profile(profile, ph, prho, p, n, scale=scale, voxel=voxel,
                                   radii=radii))
        if tried is not None and tried[1] < best:
            best, chosen = tried[1], radii
    return chosen if best[0] <= UNSEEN_SHARE * cylinder[1][0] else None


def _shoulder_starts(heights: np.ndarray, ph: np.ndarray, prho: np.ndarray,
                     voxel: float) -> list[np.ndarray]:
    """Profiles through the points' radii, each with one drop between two of them.

    Between two points neighbours in height whose radii differ by at least
    :data:`SHOULDER_RADII_VOXELS` (the :data:`SHOULDER_GAPS` largest differences), the drop
    is centred at each of :data:`SHOULDER_CENTRES` of the gap and falls linearly over each
    of :data:`SHOULDER_WIDTHS` of it; elsewhere the radii are the points' own, interpolated.
    """
    order = np.argsort(ph, kind="stable")
    h, r = ph[order], prho[order]
    jumps = np.abs(np.diff(r))
    gaps = [i for i in np.argsort(-jumps, kind="stable")[:SHOULDER_GAPS]
            if jumps[i] >= SHOULDER_RADII_VOXELS * voxel and h[i + 1] > h[i]]
    starts = []
    for i in gaps:
        below = np.interp(heights, h[:i + 1], r[:i + 1])
        above = np.interp(heights, h[i + 1:], r[i + 1:])
        gap = h[i + 1] - h[i]
        for width in SHOULDER_WIDTHS:
            for centre in SHOULDER_CENTRES:
                share = np.clip((heights - h[i] - centre * gap) / (width * gap) + 0.5, 0.0, 1.0)
                starts.append(below + (above - below) * share)
    return starts


def _unseen_highlights(surface: SurfaceOfRevolution, starts: np.ndarray, dirs: np.ndarray,
                       *, lo: np.ndarray, hi: np.ndarray, voxel: float) -> int:
    """How many highlights the surface shows its flash cameras in the domain that they missed.

    A camera at ``c`` (each distinct start of the lines ``starts``, ``dirs``) with a flash sees
    a highlight wherever the normal points at ``c``: on the meridian that faces it, at the
    heights where ``(h_c - h) + r'(h) (rho_c - r(h)) = 0`` (``h_c``, ``rho_c`` the camera's
    height and distance from the axis; crossings within a voxel of each other are one). One
    counts as seen when one of the camera's lines passes within :data:`UNSEEN_VOXELS` of it.
    Whether another part of the surface hides it is not asked, and a camera that saw nothing is
    not among the lines and asks nothing. A detector may keep only so many highlights per
    photograph (the catalogue's scenes the nearest two: a bottle seen from one ring of cameras
    shows each three), so the count is only compared between profiles.
    """
    h, r = surface.heights, surface.radii
    slope = np.gradient(r, h)
    cameras, which = np.unique(np.asarray(starts, dtype=np.float64), axis=0,
                               return_inverse=True)
    which = which.reshape(-1)
    count = 0
    for i, c in enumerate(cameras):
        hc = float((c - surface.base) @ surface.axis)
        radial = c - surface.base - hc * surface.axis
        rc = float(np.linalg.norm(radial))
        if rc <= voxel:
            continue
        g = (hc - h) + slope * (rc - r)
        facing = rc > r
        at = np.flatnonzero(facing[:-1] & facing[1:] & ((g[:-1] > 0) != (g[1:] > 0)))
        if len(at) == 0:
            continue
        apart = np.r_[True, np.diff(h[at]) > voxel]
        at = at[apart]
        x = surface.base + h[at, None] * surface.axis + r[at, None] * (radial / rc)
        x = x[np.all((x >= lo) & (x <= hi), axis=1)]
        if len(x) == 0:
            continue
        d = x - c
        dist = np.linalg.norm(d, axis=1)
        cos = (d / dist[:, None]) @ np.asarray(dirs, dtype=np.float64)[which == i].T
        off = np.arccos(np.clip(cos, -1.0, 1.0)) * dist[:, None]
        count += int(np.sum(~np.any(off <= UNSEEN_VOXELS * voxel, axis=1)))
    return count


def _points_disagree(misses: np.ndarray, scale: float) -> bool:
    """Whether the points carry noise: the profile fitted without each misses it.

    ``misses``: each point's out-of-sample distance from the profile (:func:`_fit_profile`).
    The points disagree when there are at least :data:`NOISY_PROFILE_POINTS` finite misses
    and their median exceeds :data:`NOISY_PROFILE_SIZE` of the domain's size ``scale``; a
    point no other datum predicts (its leverage one) tells nothing.
    """
    misses = misses[np.isfinite(misses)]
    return bool(len(misses) >= NOISY_PROFILE_POINTS
                and np.median(misses) > NOISY_PROFILE_SIZE * scale)


def _knots(c: np.ndarray, a: np.ndarray, lo: np.ndarray, hi: np.ndarray,
           step: float) -> np.ndarray:
    """Heights ``step`` apart along the axis ``(c, a)`` that span the domain ``[lo, hi]``."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])], dtype=np.float64)
    span = (corners - c) @ a
    count = int(np.ceil((span.max() - span.min()) / step)) + 1
    return span.min() + step * np.arange(count)


def _third_weights(heights: np.ndarray, *, scale: float, smoothness: float,
                   bend: np.ndarray | None) -> np.ndarray:
    """The weight of each third difference's row of the profile's energy (scale-free)."""
    k = (heights[1] - heights[0]) / scale
    return np.sqrt(smoothness * k) / k**3 / scale * (1.0 if bend is None else bend) * np.ones(
        len(heights) - 3)


def _profile_energy(heights: np.ndarray, radii: np.ndarray, residuals: np.ndarray,
                    angles: np.ndarray, *, scale: float, smoothness: float,
                    bend: np.ndarray | None, flat: np.ndarray) -> float:
    """The profile fit's cost: its data, third-order energy and flatness.

    The radius rows' squared ``residuals``; each line's angle (degrees, ``inf`` for a line
    that does not meet the profile) costs Tukey's loss, twice ``rho`` in radians (its square
    near zero, a line missed by :data:`SLOPE_LIMIT_DEG` or more the same as one not met: a
    profile does not cost less for losing its lines); and the flatness as a logarithm
    (:data:`FLATNESS`) over the cells ``flat`` weighs.
    """
    limit = np.radians(SLOPE_LIMIT_DEG)
    share = np.minimum(np.radians(angles) / limit, 1.0)
    lines = limit**2 / 3.0 * (1.0 - (1.0 - share**2) ** 3)
    third = radii[3:] - 3.0 * radii[2:-1] + 3.0 * radii[1:-2] - radii[:-3]
    smooth = _third_weights(heights, scale=scale, smoothness=smoothness, bend=bend) * third
    step = heights[1] - heights[0]
    slope = np.diff(radii)[flat > 0.0] / step
    flatness = (step / scale) * FLATNESS * FLAT_SLOPE**2 * np.log1p((slope / FLAT_SLOPE) ** 2)
    return float(np.sum(residuals**2) + np.sum(lines) + np.sum(smooth**2) + np.sum(flatness))


def _solve_profile(heights: np.ndarray, *, scale: float, smoothness: float,
                   values: tuple[np.ndarray, np.ndarray, np.ndarray],
                   slopes: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                   bend: np.ndarray | None = None, flat: np.ndarray | None = None,
                   leave_out: bool = False, point_misses: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares radii on the knots ``heights``, and the data rows' residuals.

    Args:
        heights: The knots (evenly spaced).
        scale: The domain's size (heights and radii are measured in it: scale-free).
        smoothness: Weight of the third-order energy.
        values: Heights, radii and weights of radius data (``w (r(h) - radius)``).
        slopes: Heights, the normal's components along the axis and outward, and weights of
            slope data (``w (n_h + n_r r'(h))``).
        bend: A weight of each third difference's row (:func:`_arc_length_weights`), or
            ``None`` for 1.
        flat: A weight of each cell's squared slope (:func:`_flatness_weights`), or ``None``
            for none.
        leave_out: Return instead of the residuals each slope row's angle (degrees) between
            its normal (``(n_r, n_h)``, of unit length with its component across the
            meridian plane) and the normal of the profile fitted without that row, at its
            height: the row's out-of-sample miss.
        point_misses: Return instead of the residuals each radius row's out-of-sample
            residual: its radius less that of the profile fitted without it, at its height.

    Every row touches at most four neighbouring knots, so the normal equations are banded
    (seven diagonals) and solved by a banded Cholesky factorisation (by a banded LU one where
    floating point leaves them not positive definite): the knots are a
    twentieth of a voxel apart (1,700 at 64 cells), and an axis' refinement solves thousands
    of profiles. The band is assembled directly, without a sparse matrix.
    """
    from scipy.linalg import cho_solve_banded, cholesky_banded, solve_banded

    count = len(heights)
    step = heights[1] - heights[0]
    k = step / scale
    rows = count - 3
    weight = _third_weights(heights, scale=scale, smoothness=smoothness, bend=bend)

    def cells(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = np.clip((h - heights[0]) / step, 0.0, count - 1 - 1e-9)
        i = np.floor(u).astype(int)
        return i, u - i

    vh, vr, vw = values
    sh, snh, snr, sw = slopes
    i, t = cells(vh)
    j, _ = cells(sh)
    n_v, n_s = len(vh), len(sh)
    # every data row has two entries, at knots c and c + 1 (lower, upper), and a target
    first = np.r_[i, j]
    lower = np.r_[vw * (1.0 - t), -sw * snr / step]
    upper = np.r_[vw * t, sw * snr / step]
    b = np.r_[vw * vr, -sw * snh]
    # the normal equations in upper banded form: band[3 - d, c + d] holds N[c, c + d]
    band = np.zeros((4, count))
    np.add.at(band[3], first, lower * lower)
    np.add.at(band[3], first + 1, upper * upper)
    np.add.at(band[2], first + 1, lower * upper)
    stencil = np.array([-1.0, 3.0, -3.0, 1.0])  # the third difference's row
    w2 = weight * weight
    for p in range(4):
        for q in range(p, 4):
            band[3 - (q - p), q: q + rows] += w2 * stencil[p] * stencil[q]
    if flat is not None:
        # each cell's slope (r[c + 1] - r[c]) / step, its length k (in the domain's size)
        wf = flat * k / (step * step)
        band[3, :-1] += wf
        band[3, 1:] += wf
        band[2, 1:] -= wf
    rhs = np.zeros(count)
    np.add.at(rhs, first, lower * b)
    np.add.at(rhs, first + 1, upper * b)
    solve = None
    if np.all(np.isfinite(band)) and np.all(np.isfinite(rhs)):
        try:
            factor = cholesky_banded(band, check_finite=False)

            def solve(x: np.ndarray) -> np.ndarray:
                return cho_solve_banded((factor, False), x, check_finite=False)
        except np.linalg.LinAlgError:
            # positive definite, yet not in floating point: the third differences' own
            # eigenvalues over 1,700 knots span some 17 orders of magnitude, and the knots
            # beyond the data are held by them alone. The banded LU factorisation with
            # pivoting solves it, as the sparse one did (bottle seed 302 at a tenth false:
            # every first fit failed so, and the grid fit was 1.3 h from the truth)
            full = np.zeros((7, count))
            full[:4] = band
            for d in range(1, 4):
                full[3 + d, :count - d] = band[3 - d, d:]

            def solve(x: np.ndarray) -> np.ndarray:
                return solve_banded((3, 3), full, x, check_finite=False)
    radii = None
    if solve is not None:
        try:
            radii = solve(rhs)
        except np.linalg.LinAlgError:  # exactly singular: LU finds a zero pivot
            pass
    if radii is None or not np.all(np.isfinite(radii)):
        # overflowing slopes or a singular system: no profile (NaN radii)
        radii = np.full(count, np.nan)
        return radii, np.full(n_s if leave_out else n_v if point_misses else n_v + n_s, np.nan)
    fitted = lower * radii[first] + upper * radii[first + 1]

    def leverage(part: slice) -> tuple[np.ndarray, np.ndarray]:
        """``z_r = N^-1 a_r`` (a column each) and the leverage ``a_r . z_r`` of rows ``part``."""
        cells = first[part]
        rows = np.zeros((len(cells), count))
        at = np.arange(len(cells))
        rows[at, cells] = lower[part]
        rows[at, cells + 1] = upper[part]
        z = solve(rows.T.copy())  # (count, rows)
        return z, np.einsum("ij,ji->i", rows, z)

    if point_misses:
        # the residual of a row left out is its residual over 1 - its leverage (as below)
        if not n_v:
            return radii, np.zeros(0)
        lever = leverage(slice(0, n_v))[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            return radii, (b[:n_v] - fitted[:n_v]) / (1.0 - lever) / vw
    if not leave_out:
        return radii, fitted - b
    # each slope row left out in turn, by the Sherman-Morrison update of the normal
    # equations: x_-i = x + z_i (a_i . x - b_i) / (1 - a_i . z_i), z_i = N^-1 a_i
    if not n_s:
        return radii, np.zeros(0)
    cols = np.arange(n_s)
    z, lever = leverage(slice(n_v, None))
    resid = fitted[n_v:] - b[n_v:]
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = resid / (1.0 - lever)
        left = radii[j] + z[j, cols] * shift
        right = radii[j + 1] + z[j + 1, cols] * shift
    slope = (right - left) / step
    # the angle between each line's normal and the profile's there, made without it
    cos = np.abs(snr - snh * slope) / np.sqrt(1.0 + slope * slope)
    cos = np.where(np.isfinite(cos), cos, 0.0)  # a row no other datum holds: unforeseeable
    return radii, angle_deg(cos)


def _point_rows(ph: np.ndarray, pr: np.ndarray, weight: float, voxel: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points' radius rows: heights and radii averaged over a voxel of height, weights.

    Each point's height and radius become the means of those of the points within half a
    ``voxel`` of its height (exact on a straight profile). A profile on the grid cannot hold
    two radii a fraction of a voxel apart in height, yet as data they ask a slope between
    them, which the third-order energy carries on as a wave: two points 0.001 apart in height
    whose radii an axis 0.23 degrees off put 0.08 voxel apart gave a bulge 2.3 voxels high
    over the body below them (bottle-lamps seed 7, 0.5 px of noise: truth->mesh 0.37 h, 0.16
    averaged). A point alone in its window keeps its own height and radius.
    """
    order = np.argsort(ph, kind="stable")
    h, r = ph[order], pr[order]
    lo = np.searchsorted(h, h - 0.5 * voxel, side="left")
    hi = np.searchsorted(h, h + 0.5 * voxel, side="right")
    count = hi - lo
    shared = count > 1

    def mean(x: np.ndarray) -> np.ndarray:
        total = np.r_[0.0, np.cumsum(x)]
        return np.where(shared, (total[hi] - total[lo]) / count, x)

    heights, radii = np.empty(len(ph)), np.empty(len(ph))
    heights[order], radii[order] = mean(h), mean(r)
    return heights, radii, np.full(len(ph), weight)


def _flat_ends(heights: np.ndarray, radii: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Beyond its outermost data the profile keeps the radius it has there.

    The third-order energy would carry the curvature on there (a neck closing on the axis),
    and a straight line carries on the slope at the last datum, which its data fix least: two
    noisy points near a bottle's base gave a steep one, and the body closed on its axis below
    them, 17 voxels off; a neck without a point above its highlights went on thinning (3.2-4.4
    voxels off at most on the neck, seeds 0-3; now 2.6-2.9). The ends of a bottle, a vase or
    a can are near cylinders.
    """
    count = len(heights)
    # the knots of the cells that hold the lowest and the highest datum
    first = int(np.clip(np.searchsorted(heights, seen.min(), side="right") - 1, 0, count - 1))
    last = int(np.clip(np.searchsorted(heights, seen.max()), 0, count - 1))
    radii = radii.copy()
    radii[:first] = radii[first]
    radii[last + 1:] = radii[last]
    return np.maximum(radii, 0.0)


def _arc_length_weights(heights: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Weights of the third differences' rows that measure the energy along the profile.

    ``(dk/ds)^2 ds``, the square of the curvature's variation per unit length of the profile,
    is ``r'''^2 (1 + r'^2)^(-7/2) dh`` to first order, so each row is multiplied by
    ``(1 + r'^2)^(-7/4)``, the slope ``r'`` taken from ``radii`` (the round before). Measured
    along the axis instead, a bend on a steep shoulder costs ``(1 + r'^2)^(7/2)`` times more
    than the same bend on a gentle one, and the fit draws the shoulder less steep than its data.
    """
    slope = np.gradient(radii, heights)
    slope = 0.5 * (slope[1:-2] + slope[2:-1])  # at the middle of each third difference
    return (1.0 + slope * slope) ** -1.75


def _flatness_weights(heights: np.ndarray, radii: np.ndarray, held: np.ndarray
                      ) -> np.ndarray:
    """Each cell's weight of its squared slope in the flatness (:data:`FLATNESS`).

    Only the cells between the lowest and the highest of the heights ``held`` (the radius
    data) have one: beyond them no datum fixes how far the profile drops, and the flatness
    made it drop less (the catalogue's bottle by flash without the points above its
    shoulder, seeds 0-5: 0.10-0.31 h without the flatness, 0.15-1.05 with it everywhere,
    0.08-0.61 between the data).
    """
    slope = np.diff(radii) / (heights[1] - heights[0])
    middle = 0.5 * (heights[1:] + heights[:-1])
    if len(held) == 0:
        return np.zeros(len(middle))
    inside = (middle >= held.min()) & (middle <= held.max())
    return np.where(inside, FLATNESS * FLAT_SLOPE**2 / (FLAT_SLOPE**2 + slope * slope), 0.0)


def _fit_profile(profile: SurfaceOfRevolution, ph: np.ndarray, prho: np.ndarray,
                 p: np.ndarray, n: np.ndarray, *, scale: float, voxel: float,
                 normals: np.ndarray | None = None, radii: np.ndarray | None = None,
                 radius_data: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 leave_out: bool = False, point_weight: float | None = None
                 ) -> ProfileFit:
    """The profile's radii: points' radii, the rays' normals where they meet it, smooth.

    Rays ``p + s n`` (``n`` inward) are traced to the current profile; the outward normal
    asked there is ``-n`` (a normal line) unless ``normals`` are given. ``radii``: the first
    profile (else a cylinder through the points' median radius). ``radius_data``: more radius
    rows (heights, radii, weights), weighed as given (:data:`LIT_HIT_WEIGHT`).

    By flash (no ``normals``: the rays are normal lines) the third-order energy is measured
    along the profile (:func:`_arc_length_weights`) and the points weigh ``point_weight``
    (:data:`PROFILE_POINT_WEIGHT` unless they are noisy). Under lamps a ray's hit moves with
    the profile: there the energy is measured along the axis and the points weigh
    ``point_weight`` (:data:`POINT_WEIGHT` unless they are noisy), as in the axis' cost (a
    coarse grid's profile drawn steeper met fewer normals, bottle-lamps at resolution 32: 2 of
    6 seeds lost; at weight 2 a quarter false on seed 3 came out 0.13 h from the clean result,
    0.09 at 20). Either way the flatness (:data:`FLATNESS`) holds the
    profile between its radius data, its weights from the round before.

    Returns the radii and, with ``leave_out``, each line's out-of-sample miss in the last
    round (degrees, NaN for a line not used; :func:`_solve_profile`, made without the
    flatness) and each point's out-of-sample distance from the profile (made with the
    flatness, each point a row of its own, not averaged as :func:`_point_rows` says), else
    ``None`` twice; and the last round's cost (:func:`_profile_energy`).
    """
    heights = profile.heights
    misses = point_misses = None
    energy = float("nan")
    if radii is None:
        radii = np.full(len(heights), float(np.median(prho)))
    outward = -n if normals is None else normals
    weights = np.ones(len(p))
    far = 2.0 * scale
    flash = normals is None
    if point_weight is None:
        point_weight = PROFILE_POINT_WEIGHT if flash else POINT_WEIGHT
    points = _point_rows(ph, prho, point_weight / voxel, voxel)
    if radius_data is not None:
        points = tuple(np.r_[x, y] for x, y in zip(points, radius_data, strict=True))
    # the rays are traced to the profile as it is returned, held flat beyond its data
    # (:func:`_flat_ends`): the third-order energy swells it there, past cameras that stand
    # beyond the data's heights, and a ray started inside it met it where it left it (bottle
    # by flash, seed 302: 28 of 42 rays every third round, and the neck's 14 lines were
    # missed by 22-25 degrees at the truth's axis; held flat, 40 of 42 met within 3)
    seen = ph
    for round_ in range(PROFILE_ROUNDS):
        current = SurfaceOfRevolution(profile.base, profile.axis, heights,
                                      _flat_ends(heights, radii, seen))
        hits, met = first_crossing(current.value, p, n, p - far * n, p + far * n,
                                   step=voxel, safety=0.5)
        hh, _, e = current.split(hits)
        # the outward normal in the meridian plane: nh + nr r' = 0 along the profile
        nh, nr = outward @ profile.axis, np.einsum("ij,ij->i", outward, e)
        use = met & (weights > 0.0) & (hh >= heights[0]) & (hh <= heights[-1])
        final = round_ == PROFILE_ROUNDS - 1
        bend = _arc_length_weights(heights, radii) if flash else None
        solve = functools.partial(
            _solve_profile, heights, scale=scale, smoothness=PROFILE_SMOOTHNESS, values=points,
            slopes=(hh[use], nh[use], nr[use], np.sqrt(weights[use])), bend=bend)
        flat = _flatness_weights(heights, radii, points[0])
        radii, out = solve(flat=flat)
        if not leave_out and not np.all(np.isfinite(radii)):
            break  # an overflowing system (a steep start's): no profile, and no more rounds
        solved = radii  # the cost is the solve's, before the radii are clipped at zero
        if final and leave_out:
            # the out-of-sample misses without the flatness: its weights come from the
            # profile each line shaped, and a false line that asked a steep slope where no
            # other datum is made the profile steep there, where the flatness then hardly
            # holds it (bottle seed 11, a quarter false: one false line missed by 12 degrees
            # out of sample, kept, 0.95 h; without the flatness by 50, left out, 0.06 h)
            out = solve(leave_out=True)[1]
            misses = np.full(len(p), np.nan)
            misses[use] = out
            # and each point's, its row its own (averaged with a point at nearly its height,
            # the other row holds it where it is)
            raw = (ph, prho, np.full(len(ph), point_weight / voxel))
            slope = np.interp(ph, heights, np.gradient(radii, heights))
            point_misses = (np.abs(solve(values=raw, flat=flat, point_misses=True)[1])
                            / np.sqrt(1.0 + slope * slope))
        radii = np.maximum(radii, 0.0)
        seen = np.r_[ph, hh[use]]
        # Tukey weights of the slopes' angles on the new profile
        current = SurfaceOfRevolution(profile.base, profile.axis, heights, radii)
        cos = np.abs(np.einsum("ij,ij->i", current.gradient(hits), outward))
        angle = angle_deg(cos)
        if final:
            energy = _profile_energy(heights, solved, out[:len(points[0])],
                                     np.where(met, angle, np.inf), scale=scale,
                                     smoothness=PROFILE_SMOOTHNESS, bend=bend, flat=flat)
        # every line counts fully until the profile has taken its shape, then robustly
        tukey = biweight(angle, SLOPE_LIMIT_DEG)
        weights = np.where(met, tukey if round_ >= PROFILE_ROUNDS // 2 else 1.0, 0.0)
    return ProfileFit(_flat_ends(heights, radii, np.r_[ph, hh[met & (weights > 0.0)]]), misses,
                      point_misses, energy)


@_finite_or_none
def fit_revolution_lit(origins: np.ndarray, dirs: np.ndarray, normals: np.ndarray,
                       points: np.ndarray, *, lo: np.ndarray, hi: np.ndarray, voxel: float,
                       axis: tuple[np.ndarray, np.ndarray], tilted: bool = True,
                       point_weight: float = POINT_WEIGHT) -> SurfaceOfRevolution | None:
    """Fit a surface of revolution to rays whose normals are known but are no normal lines.

    Under a light that is not at the camera a ray is not a normal line, but given the axis
    each ray has one point whose normal line meets it: that is its hit, which gives the
    profile's radius and slope there. The axis is the one that makes every ray's point, the
    surface points and the slopes one smooth profile: robust least squares of the profile fit's
    residuals over the axis, from ``axis`` and :data:`LIT_STARTS` directions tilted
    :data:`LIT_TILT_DEG` from it, each refined stiff then supple (:data:`LIT_STAGES`); the
    least costly wins. The profile is then refitted as by flash, its radii held between the
    points by the rays' hits (:data:`LIT_HIT_WEIGHT`).

    Args:
        origins: Ray origins ``(M, 3)``.
        dirs: Unit ray directions ``(M, 3)``.
        normals: The normal the reflection law asks of each ray ``(M, 3)``.
        points: Surface points ``(P, 3)``.
        lo: The domain's lower corner.
        hi: The domain's upper corner.
        voxel: The grid's spacing.
        axis: A first guess of the axis (a point, a unit direction).
        tilted: Also start from the :data:`LIT_STARTS` tilted directions (``False``: refine
            ``axis`` alone, when it is already near).
        point_weight: The points' weight (:data:`POINT_WEIGHT`, :data:`NOISY_POINT_WEIGHT`).

    Returns:
        The surface, or ``None`` when fewer than :data:`MIN_RAYS` rays or no point are given.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(o) < MIN_RAYS or len(pts) == 0:
        return None
    scale = float(np.max(np.asarray(hi) - np.asarray(lo)))
    data = {"o": o, "d": d, "nrm": nrm, "pts": pts, "lo": lo, "hi": hi, "voxel": voxel,
            "scale": scale, "point_weight": point_weight}
    c0, a0 = np.asarray(axis[0], dtype=np.float64), np.asarray(axis[1], dtype=np.float64)
    u, w = plane_frame(a0)[:2]
    tilt = np.tan(np.radians(LIT_TILT_DEG))
    starts = [a0] + [a0 + tilt * (np.cos(t) * u + np.sin(t) * w)
                     for t in np.linspace(0.0, 2.0 * np.pi, LIT_STARTS if tilted else 0,
                                          endpoint=False)]
    best = None
    for a in starts:
        c, a = c0, a / np.linalg.norm(a)
        for knot, smoothness in LIT_STAGES:
            c, a, cost = _refine_lit_axis(c, a, knot=knot, smoothness=smoothness, **data)
        if best is None or cost < best[0]:
            best = (cost, c, a)
    _, c, a = best
    heights = _knots(c, a, lo, hi, KNOT_VOXELS * voxel)
    hits, ok = _lit_hits(c, a, o, d, nrm)
    if ok.sum() < MIN_RAYS:
        return None
    weights = np.ones(int(ok.sum()))
    for _ in range(LIT_ROUNDS):
        radii, _ = _lit_profile(c, a, heights, hits[ok], nrm[ok], pts, weights,
                                scale=scale, voxel=voxel, smoothness=PROFILE_SMOOTHNESS,
                                point_weight=point_weight, average=True)
        # Tukey weights of each ray's radius miss, in voxels, the rays left out included (a
        # left-out row's residual is zero, so it is measured on the profile itself)
        hh, hr, _ = SurfaceOfRevolution(c, a, heights, radii).split(hits[ok])
        miss = np.abs(np.interp(hh, heights, radii) - hr) / voxel
        weights = biweight(miss, LIT_LIMIT_VOXELS)
    # then, as by flash, the normals asked where the rays meet the profile (a ray's own hit
    # above moves with the noise of its direction)
    frame = SurfaceOfRevolution(c, a, heights, radii)
    ph, prho, _ = frame.split(pts)
    keep = (ph >= heights[0]) & (ph <= heights[-1])
    from .implicit import QUADRIC_DEG, REJECT_DEG  # the start's own limits (it imports this)

    held = weights > 0.0
    kept = np.flatnonzero(ok)[held]  # the rays whose hits the profile holds

    def refit(rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> SurfaceOfRevolution:
        return SurfaceOfRevolution(c, a, heights, _fit_profile(
            frame, ph[keep], prho[keep], o[kept], d[kept], scale=scale, voxel=voxel,
            normals=nrm[kept], radii=np.maximum(radii, 0.0), radius_data=rows,
            point_weight=point_weight)[0])

    free = refit(None)
    free_misses = _misses(free, o, d, nrm, lo=lo, hi=hi, voxel=voxel)  # every ray's, once
    # the hits of the rays whose normals that profile meets, as weak radius data
    met = free_misses[kept] <= QUADRIC_DEG
    hh, hr, _ = frame.split(hits[kept][met])
    held_hits = refit((hh, hr, LIT_HIT_WEIGHT * np.sqrt(weights[held][met]) / voxel))
    # from an axis a few degrees off the hits hold the profile where no surface about that
    # axis lies, and it meets fewer normals
    misses = (_misses(held_hits, o, d, nrm, lo=lo, hi=hi, voxel=voxel), free_misses)
    shares = [np.array([np.mean(m <= QUADRIC_DEG), np.mean(m <= REJECT_DEG)]) for m in misses]
    return held_hits if np.all(shares[0] >= shares[1]) else free


def _misses(surface: SurfaceOfRevolution, o: np.ndarray, d: np.ndarray, nrm: np.ndarray,
            *, lo: np.ndarray, hi: np.ndarray, voxel: float) -> np.ndarray:
    """Each ray's miss: the angle (degrees) between its normal and ``surface``'s.

    Measured where the ray first crosses ``surface``; 180 for a ray that misses it.
    """
    x, inside = surface.intersect(o, d, lo, hi, step=voxel)
    return miss_deg(surface.gradient(x), nrm, inside)


def lit_hit_distance(surface: SurfaceOfRevolution, o: np.ndarray, d: np.ndarray,
                     nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far each ray's own hit lies from ``surface``, and whether the ray has one.

    A ray's hit is where its normal line meets the surface's axis (``_lit_hits``); the
    distance is ``surface``'s first-order distance there (world units).
    """
    hits, ok = _lit_hits(surface.base, surface.axis, o, d, nrm)
    return np.abs(surface.value(hits)), ok


def _lit_hits(c: np.ndarray, a: np.ndarray, o: np.ndarray, d: np.ndarray,
              nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point of each ray whose normal line meets the axis, and whether there is one.

    Solves ``o + t d + s N = c + v a``; the hit lies ahead of the camera (``t > 0``) and the
    axis behind the surface (``s < 0``).
    """
    A = np.stack([d, nrm, -np.broadcast_to(a, d.shape)], axis=2)
    ok = np.abs(np.linalg.det(A)) > 1e-6
    sol = np.zeros((len(d), 3))
    if ok.any():
        sol[ok] = np.linalg.solve(A[ok], (c - o)[ok][..., None])[..., 0]
    ok &= (sol[:, 0] > 0.0) & (sol[:, 1] < 0.0)
    return o + sol[:, :1] * d, ok


def _lit_profile(c: np.ndarray, a: np.ndarray, heights: np.ndarray, hits: np.ndarray,
                 nrm: np.ndarray, pts: np.ndarray, weights: np.ndarray, *, scale: float,
                 voxel: float, smoothness: float, point_weight: float, average: bool = False
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The profile through the points and the rays' hits with their slopes.

    Returns the radii and the residuals: radii in voxels (points weighed by ``point_weight``,
    then the hits), then the slopes (in units of the normal). ``average``: the points'
    heights and radii averaged over half a voxel of height (:func:`_point_rows`); not in the
    axis' cost, whose rows are one per point.
    """
    frame = SurfaceOfRevolution(c, a, heights, np.zeros(len(heights)))
    hh, hr, e = frame.split(hits)
    ph, pr, _ = frame.split(pts)
    sw = np.sqrt(weights)
    if average:
        ph, pr, _ = _point_rows(ph, pr, point_weight / voxel, voxel)
    values = (np.r_[ph, hh], np.r_[pr, hr],
              np.r_[np.full(len(ph), point_weight / voxel), sw / voxel])
    slopes = (hh, nrm @ a, np.einsum("ij,ij->i", nrm, e), sw)
    return _solve_profile(heights, scale=scale, smoothness=smoothness, values=values,
                          slopes=slopes)


def _lit_residuals(c: np.ndarray, a: np.ndarray, o: np.ndarray, d: np.ndarray,
                   nrm: np.ndarray, pts: np.ndarray, *, lo: np.ndarray, hi: np.ndarray,
                   voxel: float, scale: float, knot: float, smoothness: float,
                   point_weight: float) -> np.ndarray:
    """The profile fit's residuals for the axis ``(c, a)``: points, rays' radii, slopes."""
    heights = _knots(c, a, lo, hi, knot * voxel)
    hits, ok = _lit_hits(c, a, o, d, nrm)
    out = np.full(len(pts) + 2 * len(o), LIT_NO_HIT)  # a ray without a hit costs
    _, res = _lit_profile(c, a, heights, hits[ok], nrm[ok], pts, np.ones(int(ok.sum())),
                          scale=scale, voxel=voxel, smoothness=smoothness,
                          point_weight=point_weight)
    index = np.flatnonzero(ok)
    out[: len(pts)] = res[: len(pts)]
    out[len(pts) + index] = res[len(pts): len(pts) + len(index)]
    out[len(pts) + len(o) + index] = res[len(pts) + len(index):]
    return out


def _refine_lit_axis(c: np.ndarray, a: np.ndarray, *, knot: float, smoothness: float,
                     **data) -> tuple[np.ndarray, np.ndarray, float]:
    """The axis near ``(c, a)`` whose rays' hits and points make the smoothest profile."""
    from scipy.optimize import least_squares

    unpack = _axis_moves(c, a, data["voxel"])
    fit = least_squares(
        lambda x: _lit_residuals(*unpack(x), knot=knot, smoothness=smoothness, **data),
        np.zeros(4), loss="cauchy", f_scale=LIT_SCALE, diff_step=1e-3)
    cx, ax = unpack(fit.x)
    return cx, ax, float(fit.cost)
