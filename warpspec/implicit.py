"""The implicit start: any shape and topology, chosen from the data, solved coarse to fine.

1. A first guess from where the cameras stand: when they surround the data (no half-space
   through the rays' convergence point holds them all), a sphere around that point through the
   points; otherwise the paper's plane through the points, facing the cameras.
2. A quadric fitted to the rays and points (:mod:`warpspec.quadric`). When it meets the
   normals within noise it is the start: spheres, ellipsoids, cylinders, paraboloids.
3. Otherwise a smooth function ``f`` on a coarse-to-fine ladder of grids (16, 32, ... up to
   the requested resolution), fitted to the points (``f = 0``) and to the normals the
   reflection law demands where the specular rays meet its current zero set (``grad f = N``),
   with the Hessian energy of the correction to the quadric as the smoothness (Smooth Signed
   Distance reconstruction); the rays are intersected again and ``f`` refitted, a few rounds on
   each level, each level started from the one below. The depth of a highlight is unknown, so
   no value is asked of ``f`` at a ray's hit: the surface's offset comes from the points, its
   shape from the normals, carried across by the smoothness. Rays that miss the current
   surface pull it, weakly, toward where they pass nearest. The points are held nearly
   exactly, unless fits made without each of them find them noisy
   (:meth:`ImplicitStart._noisy_points_grid`).
4. Each ray is weighed robustly (Tukey's biweight on the angle between ``grad f`` and ``N``);
   a highlight whose normal cannot be met with the others (a false detection, another light's
   reflection) is rejected and reported instead of bending the surface. A supple fit follows
   a false normal too, so rejection is decided by robust passes on the coarse levels, stiff to
   supple (:data:`ROBUST_SMOOTHNESS`); a rejected ray that the final fit, made without it,
   meets after all comes back, and the ladder is refitted from that fit
   (:data:`RETURN_ROUNDS`); then the rays still rejected are tried back together, and stay
   when each is met beside another and the kept rays' median miss does not grow (by more
   than its standard error, where every ray tried stays); when none does, they are tried at
   full weight, and each must also be met by a fit made with the others but without it
   (:meth:`ImplicitStart._trial_return`).
   Last, cross-validation finds the false normals a supple fit follows: each kept ray's normal
   is compared with a coarse fit made without it (:meth:`ImplicitStart._cross_validate`);
   the worst of those missed by more than CV_DEG (CV_HULL_DEG where the fit without it
   extrapolates) are rejected, pass after pass, and the ladder refitted; a ray that fit meets
   after all comes back once more, and the rest are tried back together again.

See docs/DESIGN.md section 7.
"""


from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from . import ellipsoid as E
from . import quadric as Q
from . import revolution as R
from . import torus as T
from ._parallel import launch_halves
from .geometry import LIGHT_CAMERA, LIGHT_POINT, angle_deg, best_fit_plane, miss_deg, plane_frame
from .grid import Grid
from .kernels import implicit as K
from .mesh import sample_trilinear
from .normal_lines import best_axis
from .pixel_fit import point_pixels

__all__ = ["FitReport", "ImplicitStart", "fill_pockets", "first_guess", "level_ladder",
           "ray_convergence", "sphere_guess", "surrounds"]

MIN_CONSTRAINTS = 3
"""Fewest rays entering the domain plus points below which nothing is fitted."""
COARSEST = 16
"""Cells along the longest side of the coarsest level of the ladder."""
QUADRIC_DEG = 3.0
"""The quadric alone is the start when at least QUADRIC_SHARE of the rays' normals are met this
closely,..."""
QUADRIC_SHARE = 0.7
QUADRIC_AMBIGUOUS = 0.05
"""...no more than this share are off by between QUADRIC_DEG and REJECT_DEG (false highlights
are further off; a shape that is not a quadric falls away gradually),..."""
PIXEL_NOISE = 5.0
"""...(a normal missed by more than QUADRIC_DEG still counts as met when its highlight need
move no more than PIXEL_MET pixels for the shape to meet it, or, when no shape is the start
so, no more than this many, or more where the shape's rays show more noise (NOISE_SPREAD): noise
on the highlights, which moves a grazing ray far along the surface),..."""
PIXEL_STEP = 0.5
"""The move of a highlight (pixels) over which the change of a ray's miss is measured."""
QUADRIC_POINT_SIZE = 2.0 / 64.0
"""...and it holds the points: their median distance from it is within this share of the
domain's largest side (two voxels at resolution 64, whatever the grid: the shape taken
does not change with it),...
Points from structure from motion carry noise, which the fit takes into its depth; the rule
lets through noise of up to a voxel per axis. The median distance of such points from their
own surface is 0.67 voxel, and of eight of them it passes 1.5 voxels about once in 280
draws, 2 about once in 40,000; a fitted shape leaves them further (the torus, a robust fit,
passes through some points and leaves the others): one draw's eight lay at a median of 1.44
voxels from the torus that met every normal, and at 1.51 from the one under a point lamp.
At a voxel and a half that torus was refused, and four more shapes that met the normals
(points a voxel off per axis, 0.5 px on the highlights): the grid fits in their place were
refused or came out 0.78-1.69 h off, the shapes 0.07-0.43 h. On every
scene of the catalogue the shape that meets the normals holds its exact points within 0.07
voxel, and every shape refused is refused by its normals; a shape of the wrong kind (a
quadric on a bottle) misses most points by voxels. When 4 in 5 points had to lie within a
voxel, a torus whose eight points were moved by half a voxel per axis (all within 1.2 voxels
of it, two beyond one) was refused, and the grid fit met 38 of 58 rays instead of every one."""
QUADRIC_POINT_SHARE = 0.8
"""...with at least this share of them within QUADRIC_POINT_REACH."""
QUADRIC_POINT_REACH = 3.0 / 64.0
"""Three voxels at resolution 64: noise of a voxel per axis puts about one point in 370 this
far; a shape that holds half the points but misses the rest by more is not their shape."""
PIXEL_MET = 3.0
"""The pixels a highlight may need to move for a closed-form shape to meet its normal and the
ray count as met, first; and the rays kept for the flow are those met so (those met only
within PIXEL_NOISE count for the shape, not for the surface). Under a point lamp, at 1 px of
noise per axis, the true torus missed normals by 5-8 degrees, but none by more than 3.2 px.
At 2 px a third of the highlights lie more than 3 px from their true place, and the true
shapes need moves of up to 6.6 px: the tori were refused (torus-point, torus-lamps and the
torus by flash, seeds 0-5: all 18), and the grid fits in their place came out 0.10-0.63 h
off, under a point lamp 0.43-0.63. Judged with 5 px, 15 of the 18 are the start, and the
pebble seed 0 (0.18 h by the grid fit): 0.03-0.33 h end to end. Taken at once, 5 px let
cruder fits through before their refinements ran (the bottle under lamps, seed 4, a tenth
false and 1 px: a false highlight kept, 0.10 -> 0.21 h), and grazing rays kept at 5 px
dented the surface (the pebble at 2 px, seed 3: 0.05 -> 0.13 h). Over 1,073 catalogue scenes
(every class, seeds 0-5: clean, a tenth and a quarter false, 0.5, 1 and 2 px, a tenth false
with 1 px, and points half a voxel or a voxel off; the blob, the free-form patch and the
point-lit dome, seeds 6-59) no other start changed; wrong shapes lie far off in pixels (the
blob's quadric 12-17 px in the median, the free-form patch's 130-560)."""
NOISE_SPREAD = 3.5
"""Judged the second time (PIXEL_NOISE), a shape's allowance is this many times the noise its own
rays show (:func:`_noise_allowance`), at least PIXEL_NOISE and at most PIXEL_WIDEST (a surface
of revolution keeps PIXEL_NOISE as it is fitted:
:meth:`ImplicitStart._best_revolution_by_noise`). Under Gaussian noise of sigma pixels per axis
on the highlights, the true shape's pixel misses follow Rayleigh's law (median 1.18 sigma; one
in 460 beyond 3.5 sigma). At 2 px, 5 px fixed refused true tori for 3-5 rays in 46-58 (more than
QUADRIC_AMBIGUOUS) whose highlights lay 5.0-6.7 px off: the torus by flash seeds 2, 3, 700, 801
and 803, under lamps seeds 3 and 700, under a point lamp seeds 702 and 801 (their medians
2.0-3.1 px); the grid fits in their place came out 0.12-0.17 h off, under the point lamp 0.55
and 0.42 (in 217-233 s), and with the tori as the start 0.05-0.12 h (in 3-9 s; two runs at a
time)."""
PIXEL_WIDEST = 8.0
"""...: noise of up to 2.3 px. A wrong shape misses its rays by tens of pixels in the median
(the blob's quadric 11-19, the point-lit dome's 3-22), and it meets few more of them with 8 px
than with 5: over 260 catalogue scenes (every class, seeds 0-2: clean, a quarter false, 1 and
2 px, a tenth false with 1 px; seeds 3-5 at 2 px; the tori also at 1.5 px, a tenth false with
2 px, and seeds 700-702 and 801-803 at 2 px; the blob, the free-form patch, the point-lit dome
and the bottle, seeds 3 and 4, a tenth false with 2 px) no shape refused with 5 px but the true
tori above and two surfaces of revolution would be taken with 8. Those two are the bottle under
lamps at 2 px, seeds 3 and 4, whose refits (while each meets more normals: LIT_REFITS) stop at
the first taken: at seed 4 a first fit that met 84% of the normals within 3 degrees where its
refit met 95% (1.01 h; the grid fit 0.53), at seed 3 a good one (0.23 h; the grid fit 0.90)."""
NOISY_POINT_GAIN = 0.5
"""The quadric is refitted with the points weighed as noisy
(:data:`~warpspec.quadric.NOISY_POINT_WEIGHT`, not POINT_WEIGHT's near-exact hold), and the
refit is the start when it meets the normals this much closer (the median miss) and is the
start by itself. Points from structure from motion carry noise; held exactly, six points half
a voxel off (per axis) bend a quadric's nine coefficients away from the normals: on the sphere
seen all around by flash the median miss was 1.69 degrees held and 0.09 let go, on the
ellipsoid under lamps 2.59 and 0.25 (refused held: 71% of the normals within 3 degrees). With
exact points and 1-2 px of noise on the highlights both fits meet the normals alike (0.26 and
0.23 degrees, 0.51 and 0.41), and the points held exactly fix the depth better. A lit surface
of revolution is refitted so too (:meth:`ImplicitStart._noisy_points_revolution`): bottle-lamps,
seeds 0-5, points half a voxel off, the refit's median miss 0.19-0.41 times the held one's;
exact points with 0.5-1 px, 0.81-1.2 times."""
NOISY_POINT_DEG = 0.5
"""...and when the quadric that holds the points misses the normals by at least this much (the
median): with exact points and highlights both fits meet them within hundredths of a degree,
and the points held fix the depth. A lit surface of revolution needs no such floor: its held
profile missed by a median of 0.38 degrees lay 0.18 voxel from the truth (bottle-lamps seed 2,
points half a voxel off, one iteration), its refit 0.13 degrees and 0.03 voxel, and
with exact points it was taken once over the catalogue (432 scenes), with the same result."""
NOISY_REFIT_GAIN = 0.8
"""A torus is refitted with the points weighed as noisy (:func:`warpspec.torus.refit_torus`),
and the refit replaces the torus that was the start when its rays pass the points with the
normals they ask this much closer (the median, in pixels: :func:`warpspec.torus.pixel_misses`)
and it is the start by itself; an ellipsoid's refit must do so too (NOISY_POINT_RATIO).
Under a lamp the rays fix the tube's radius, which the fit to normal lines takes from the
points: torus-lamps and torus-point, seeds 0-13, points a voxel
off per axis and half a pixel on the highlights, the held tori up to 0.82 voxel off, the
refits within 0.18 (a median of 0.03); the refits' median miss 0.26-1.05 times the held
ones', above 0.8 only where those were within 0.14 voxel. With exact points and 1 px on the
highlights the refit fits the noise (its tube up to 0.6 voxel off, the held one's within
0.07): 0.72-1.41 times, 0.8 or less three times in 28, and those refits within 0.05."""
NOISY_TORUS_RATIO = 0.6
"""...and it is refitted only when the points lie at least this many times further from it than
its rays pass the points with the normals they ask (medians, both in pixels, as
NOISY_POINT_RATIO): when the noise is in the highlights, not the points, the refit fits it.
By flash the rays leave the tube's radius to the points, and the refit of a torus whose exact
points it held, with 2 px on the highlights, thinned the tube by 0.6-1.6 voxels (seeds 0-11;
by 0.2-0.5 at 1 px). The torus, torus-lamps and torus-point scenes, seeds 0-11: with exact
points and 0.5-2 px on the highlights 0.02-0.47; points half a voxel off per axis, or a voxel
with 0.5 px, 0.87-84."""
NOISY_POINT_RATIO = 3.0
"""A quadric start that is an ellipsoid is refitted in pixels with the points weighed as noisy
(:func:`warpspec.ellipsoid.refit_ellipsoid`), and the refit replaces it when it is the start by
itself and the points lie this many times further from it than its rays pass the points with
the normals they ask (medians, both in pixels: a point's distance over a pixel's width at its
depth, :func:`warpspec.pixel_fit.point_pixels`, and :func:`warpspec.ellipsoid.pixel_misses`):
the points carry more noise than the highlights. The sphere by flash, the ellipsoid and the
pebble under lamps and the ellipsoid cap under a point lamp, seeds 0-11: with exact points and
0.5-1 px on the highlights 0.06-2.4 (96 scenes); points half a voxel off per axis, 215-1386;
a voxel off with 0.5 px, 6-28, and 2.4 for one sphere by flash (whose rays leave its radius to
the points: held 0.77 voxel off, refit 0.64). The ratio of the two fits' pixel misses, the
torus' test, was 0.75-1.2 and 0-0.78: taken at 0.8 alone, seven refits on exact points were
0.03-1.07 voxel off where the quadrics that held them were within 0.11. The refit must pass
both (NOISY_REFIT_GAIN): with exact points and 2 px on the highlights, the sphere by flash
(whose rays leave the radius to the points), seeds 0-3, passed this test: the refit, free
of the points, bent to the highlights' noise and left them a voxel off, and met the rays no
closer (0.88-1.06 times the held fit's misses): the sphere 0.94-1.09 h from the truth,
0.02-0.04 held. Points half a voxel off, or a voxel with 0.5 px, seeds 0-3: the sphere's
refits 0-0.62 times, the pebble's 0.001-0.37, each taken as before."""
CONSENSUS_RAYS = 6
"""When neither the quadric fitted to every ray, nor a torus, nor a surface of revolution is
the start, fits to random subsets of this many rays (and every point) look for a quadric that
is: false highlights can drag the fit of every ray into a wrong quadric before its robust
weights start (the ``pebble`` scene, seed 9, a quarter false: 0 of 28 normals met from any
start), while in a subset they are few, and its own robust weights drop them. Six rays and
the points fix a quadric's nine coefficients; on that scene 12 of 40 subsets of six found
the quadric that meets every true normal."""
CONSENSUS_TRIALS = 16
"""Most subsets tried (the search stops at the first that gives the start). At three in ten
finding it, 16 miss with odds under 1 in 300. A shape that no closed form fits (the grid
fit's, seconds) pays for every trial, 0.2-0.3 s in all."""
REJECT_DEG = 10.0
"""A ray whose normal a robust pass misses by more than this, and by more than REJECT_SIGMAS
robust standard deviations of the kept rays' misses, is rejected as false."""
REJECT_SIGMAS = 3.0
"""Robust standard deviations (1.4826 times the median miss) beyond which a pass rejects a ray.
Three, not four: on the point-lit dome with a quarter of its highlights false, a stiff pass's
false misses (11-53 degrees, seed 6) sit among four standard deviations (22) of the misses they
inflate."""
RETURN_DEG = 15.0
"""A rejected ray comes back when the final fit, made without it, meets its normal this closely
(or within the kept rays' threshold): a miss out of sample is larger than one in sample."""
LIMIT_DEG = 30.0
"""Smallest Tukey limit of the grid fit's soft robust weights: the fit cannot follow every
legitimate normal before it has converged, so only normals this far off lose all weight."""
ROBUST_SMOOTHNESS = (10.0, 5.0, 2.5, 1.2, 0.6, 0.2)
"""Smoothness (as SMOOTHNESS) of the robust passes, stiff to supple, on the levels up to
ROBUST_TOP."""
ROBUST_TOP = 32
CV_FOLDS = 64
"""Most folds of a cross-validation pass: with up to this many rays kept, each coarse fit leaves
out one ray (leave-one-out) and checks its normal where it meets that fit. A supple fit follows
a false normal in sample, so the robust passes catch only the false normals that no smooth
surface meets; out of sample, a false one is missed by what it disagrees with its neighbours.
On the free-form patch (60 highlights) at 64 cells, seeds 3, 5, 7 and 12: with 6 false, 10
folds and a limit of 3 robust standard deviations kept 2-4 false highlights on seeds 3 and 12,
these passes none (the error 0.14 and 0.18 h, as the clean scenes' 0.13 and 0.18); with 15
false, 1-4 were rejected and the surface was 0.63-0.78 h off, now 6-11 and 0.23-0.46 h (the
false ones removed by hand: 0.16 h on seed 12). Leaving out a tenth at a time removes the
neighbours that would tell a true feature apart, and the robust spread of misses made with a
quarter false grows with them."""
CV_DEG = 10.0
"""A cross-validation pass rejects a ray whose normal the fit made without it misses by more
than this (degrees), or by more than CV_HULL_DEG where the ray meets the reference at a corner
of the kept hits' hull, and of the first pass's (seen from one side), with no other hit as
near as the hits' median spacing (CV_NEAR): there a fit without it extrapolates. The passes
fit the finest level up to ROBUST_TOP (32 cells at 64): at 16 cells the fit cannot hold the
free-form patch's bump, and true normals were missed out of sample by up to 15-18 degrees,
with 60 highlights or 120, as many false ones were (10-20). At 32 cells, clean, with 120
highlights, none was missed by more than 6.4 (false: mostly 12-30). Free-form patch, seeds
0-7 with 60 highlights and 0-3 with 120, error against the clean scene's: with a tenth false,
seven of eight within 0.1 h (five at 16 cells with 15 and 30 degrees) and four of four; with
a quarter, 0.02-0.33 h (0.01-0.39) and three of four (two); the clean scenes unchanged."""
CV_HULL_DEG = 15.0
"""The out-of-sample miss (degrees) beyond which a hull corner is rejected (CV_DEG). False
highlights often stand there: a glint drawn anywhere on the object lands beyond the true
highlights about as often as among them (45% of the free-form patch's domain lies beyond).
The free-form patch (seeds 0-7, 200-203, 400, 401, 60 highlights), first pass: clean, the
true corners were missed by at most 6.9 (4 of 81 over 5); with a tenth or a quarter false,
the false corners by 0.9-19.5 (median 7.4, 46 of them), the true ones by up to 19.5 (10 of
115 over 7), bent by the false ones beside them. At 10 degrees, seed 203 at a tenth false
went 0.35 -> 0.17 h, but seeds 1 and 2 at a quarter 0.47 -> 0.55 and 0.18 -> 0.24 (over the
clean scene's region), and nothing else moved by more than 0.011 h (the point-lit dome's
seeds 0-7 not at all)."""
CV_FLOOR_DEG = 5.0
CV_GAP = 2.0
"""Cross-validation's gap rule: an inner ray missed out of sample by more than CV_FLOOR_DEG
(degrees) and CV_GAP times every other inner ray is rejected too, under CV_DEG: where fits
made without each ray foresee the rest closely, a false normal stands alone. The blob at a
tenth false, seed 1: false highlight 30 was missed by 7.8 degrees, the true ones by at most
3.1 (median 1.0); kept, the blob was 0.107 h worse than the clean scene, rejected 0.022
(seed 102: 8.3 against 3.75, +0.114 -> +0.025 h). Not a limit from the spread of the misses
(three robust standard deviations, at least CV_FLOOR_DEG): the free-form patch's true misses
have a long tail, and seed 1 at a tenth false went from 0.220 to 0.328 h, clean seed 4 from
0.060 to 0.090. Seen all around, that limit holds as well (:meth:`ImplicitStart._spread_miss`):
no patch edge or feature seen from one side makes a tail there. The blob at a quarter false,
seed 501: false highlights 32 and 24 were missed by 8.1 and 5.9 degrees, the true ones by at
most 2.9; a pair, neither alone, both were kept, 0.34 h from the truth (0.14 clean); with 32
rejected, 24 is met within 1.5 and kept, 0.24 h. No other run of the blob's seeds 0-7 and
500-503, clean, a tenth and a quarter false, moved."""
CV_NEAR = 1.0
"""A corner of the kept hits' hull whose nearest other hit is no farther than this share of the
hits' median distance to their nearest is cross-validated as an inner ray (CV_DEG): a fit
without it is carried there from that hit, not extrapolated. (The point-lit dome at a quarter
false, seed 6: false highlight 5 at 0.29 of the median spacing; the free-form patch's true
corner ray with 30 highlights, seed 0, at 1.05.) Half the median spacing fixes the dome alike,
but of the free-form patch's runs (seeds 0-7, 10% and 25% false) it gives back the two that
the median improves (seed 2 at 25%: +0.091 h from the clean scene -> +0.125; seed 4 at 10%:
+0.008 -> +0.047)."""
CV_SHARE = 0.05
"""Most rays (a share of those kept) one cross-validation pass rejects, the worst missed first:
with a quarter false, the fits of a pass are bent by the other false highlights too, and true
highlights near them are missed by as much; the next pass, made without the worst, tells them
apart."""
CV_PASSES = math.ceil(math.log(0.5) / math.log(1.0 - CV_SHARE))
"""Most cross-validation passes (14): enough to reject half the rays kept, CV_SHARE at a time.
Each refits its reference from the one before's, without the rays rejected so far. Rays
rejected on the way come back when the final fit meets them (:meth:`ImplicitStart._bring_back`,
:meth:`ImplicitStart._trial_return`), so the passes must be able to go on until none is
missed. With 8 (a third of them) the free-form patch at a quarter false, seed 302, stopped
while 5 rays were still missed beyond the limits: a fit that 15 false highlights bent had
rejected 14 true ones first, and the patch was 1.05 h from the truth. Its passes end at the
tenth, 9 false and 1 true rejected in the end (0.60 h). No other scene of the command line's
table ran out of passes."""
TORUS_ROUNDS = 20
"""Most fit-and-intersect rounds of the torus when some rays are not flash-lit (normal lines
through the rays' hits). Each round's hits are the mean of the last round's and those on the
new torus: under a point light the normals move with the hits, and undamped, the rounds swung
about the torus, ever further (a torus lit by a lamp 3 away: its centre 0.009, 0.010, 0.016,
0.024, 0.036 off along its axis in turn, 1.8 voxels off at the end, not watertight); damped,
they close in on it (torus-point seeds 0-5: each result 0.035-0.041 voxel from the truth),
and the round that meets the most normals is taken."""
TRUSTED_SHARE = 0.7
"""After its first round, the torus is fitted to the normal lines of the rays the last one met
within REJECT_DEG, or of this share of them, the closest met: a quarter false, under a point
lamp, never left half the rays within REJECT_DEG of a torus fitted to them all."""
SETTLED_VOXELS = 0.01
"""The torus' rounds stop when no ray's hit moves further than this (voxel widths)."""
LIT_REFITS = 2
"""Most fits of a surface of revolution under lamps after the first (which takes the rays that
meet the quadric), each from the axis of the normal lines through the rays' hits on the one
before and only the rays it met within REJECT_DEG (while each meets more normals; one that
does not is followed by one last fit to only the rays it meets within QUADRIC_DEG). The one
taken, when it was fitted with rays it rejects, is fitted once more without them, and that fit
replaces it when it is the start by itself too (it is fitted to fewer rays, none of them one
that the shape taken rejects). When none of them is taken, every ray is fitted once more from
the axis of the one that met most normals within QUADRIC_DEG."""
FINE_ABOVE = 32
"""Levels finer than this many cells get the requested grid's budget (ROUNDS_FINE rounds of at
most CG_ITERATIONS_FINE): they start from the level below and only correct its detail."""
ROUNDS_COARSE = 4
"""Intersect-and-refit rounds on each coarse level."""
ROUNDS_FINE = 2
"""Intersect-and-refit rounds on the requested grid (and the levels above FINE_ABOVE)."""
CG_ITERATIONS = 200
"""Conjugate-gradient iterations of one fit on a coarse level, at most."""
CG_ITERATIONS_FINE = 25
"""Conjugate-gradient iterations of one fit on the requested grid (and the levels above
FINE_ABOVE), at most."""
CG_BLOCK = 10
"""Conjugate-gradient iterations between two checks of the residual (one graph replay)."""
GRAPH_NODES = 100_000
"""Levels with fewer nodes replay their CG blocks as graphs (launch overhead dominates
there); larger ones launch directly, their stencils in two slabs on two CPU cores."""
CG_TOLERANCE = 1e-5
"""Stop a fit when the residual norm has fallen by this factor."""
SMOOTHNESS = 0.02
"""Weight of the Hessian energy per unit of the domain's length (``lam = SMOOTHNESS h / L``) in
the final fit. Beside the third-order energy it holds the long waves, which the third order
leaves almost free: at 0.002 (and 0.01) a free-form patch seen by cameras near its horizon grew
a ridge 5 voxels high that met every normal."""
THIRD = 3e-4
"""Weight of the third-order energy ``|D^3 f|^2`` (``lam3 = THIRD L / h``) of the final fit.
It carries the bends across between sparse highlights. Truth to mesh on the free-form patch:
with 30 highlights 0.23-0.70 h on seeds 0-11 (0.24-0.92 at 1e-4); on its worst seeds (0, 3,
6, 9-11) 0.43-0.70 h, 0.48-0.92 at 1e-4, 0.38-0.70 at 1e-3 and 0.65-1.72 at 1e-5. With 60,
0.06-0.24 h on seeds 0-5 (0.09-0.24 at 1e-4; 0.11-0.29 at 1e-3 on seeds 0-2); with 120 and
240 (seeds 0-2, 0-1) within 0.015 h of 1e-4. The point-lit dome (seeds 0-8, clean and a
quarter false) moved by at most 0.016 h."""
POINT_WEIGHT = 20.0
"""Weight of ``(f(y) / h)^2`` at a point constraint, against 1 for a unit normal error."""
NOISY_GRID_POINT_WEIGHT = 0.02
"""The grid fit's point weight when its points are judged noisy
(:meth:`ImplicitStart._noisy_points_grid`): a voxel off weighs as a normal 8 degrees off, so
the normals shape the surface and the points together fix its depth. Points from structure
from motion carry noise, and held at POINT_WEIGHT each bends the fit to itself: the point-lit
dome with its points half a voxel off per axis (seeds 0-7, the command line) was 0.23-0.62 h
from the truth held, 0.12-0.44 at this weight."""
NOISY_GRID_RATIO = 0.75
"""The points are judged noisy when fits made without each of them, the points at
NOISY_GRID_POINT_WEIGHT, pass nearer to it (the median distance) than this share of what the
fits at POINT_WEIGHT do. Exact points are foreseen as well or better held (a held fit follows
the surface through its neighbours); a noisy point is foreseen by neither, and the fits held
bend to the noise of the others. Over 40 scenes (the point-lit dome seeds 0-7 and 20, the
free-form patch seeds 0-3, the blob seeds 0-1; exact points and points half a voxel off) the
share was 0.34-0.72 on five of the dome's noisy scenes (seeds 0, 1, 3, 4, 5) and its clean
seed 3, each closer to the truth at the noisy weight (by 0.05-0.33 h), and at least 0.78 on
every other; but see NOISY_GRID_GAIN."""
NOISY_GRID_GAIN = 0.9
"""...and the refit at the noisy weight is taken when its median normal miss (the kept rays) is
below this share of the held fit's: noisy points held bend the surface off the normals. The
judgement out of sample alone cannot tell noise from a shape the normals leave open between
the points: the clean point-lit dome seed 500 and free-form patch seed 202 passed it (0.32
and 0.63) and came out 0.11 -> 0.20 and 0.14 -> 0.21 h; their refits met the normals no
closer (0.135 -> 0.129 and 0.270 -> 0.281 degrees), where those taken did (the dome seed 3
clean 0.203 -> 0.166, points half a voxel off seeds 1, 3 and 5 0.30 -> 0.15, 0.29 -> 0.20,
0.24 -> 0.15, seed 500 a quarter false 0.139 -> 0.109)."""
NOISY_GRID_POINTS = 4
"""Fewest points the grid fit's noise judgement is made with (a median of fewer says little),
and the comparison of two grid fits by their points (PRIOR_POINTS_RATIO)."""
PRIOR_POINTS_RATIO = 2.0
"""Two grid fits about different priors (:func:`_better_fit`): when the fits made
without each point (:meth:`ImplicitStart._point_misses`, the points held) pass this many times
nearer to it about one prior than about the other (the median distance), that prior's fit is
taken; otherwise the one that explains more kept rays (:meth:`ImplicitStart._fit_score`). The
rays a fit keeps are met in sample, and a fit that keeps false highlights meets them too; the
points are out of sample, and no false highlight touches them. The free-form patch, seed 17:
a ring torus meets more normal lines than the quadric, and the fit about it keeps 11 of 15
false highlights at a quarter false (5 of 6 at a tenth) and meets 50 kept rays (55), the
fit about the quadric keeps 4 (3) and meets 47 (54); the points left out lie 0.86 and 0.28
voxel from the fits in the median (0.26 and 0.08). By the rays the torus' fit was taken,
1.11 h from the truth (0.42 at a tenth), by the points the quadric's, 0.19 (0.19; clean
0.085). Where the rays tell right too, the points agree: the blob seed 10 at 32 cells, the
tube's fit 0.18 and the quadric's 0.05; the bottle under lamps on one ring (seed 0, its
shape no start), the surface of revolution's 0.37 and the quadric's 3.8. Clean, seed 17:
0.10 about the torus, 0.14 about the quadric (a ratio of 1.5), and the rays keep the
quadric's. Over 47 runs (the free-form patch, seeds 0, 1, 3-10, 16-23 and 302 at a quarter
false, seeds 0, 1, 3-10, 17 and 302 clean and at a tenth; the blob, seeds 0, 1, 5 and 501)
only seed 17's grid fits were made about two priors."""
MISS_WEIGHT = 0.5
"""Weight of ``(f(a) / h)^2`` at the nearest approach ``a`` of a ray that misses."""
PROXIMITY = 1e-5
"""Weight of ``((f - f_prev) / h)^2`` per node: fixes the null space, moves nothing."""
SAMPLE_OFFSETS = (-0.5, 0.0, 0.5)
"""Gradient samples along each ray around its anchor, in voxel widths of the level."""
SAMPLE_WEIGHTS = (0.5, 1.0, 0.5)
COLUMNS = 33
"""Lines per side of the sweep that checks a one-sided prior for a second sheet."""
RING_LENGTH = 0.4
"""Under lamps, cameras that a half-space holds are tried for a surface of revolution only
when their mean direction (:attr:`Guess.lean`) is shorter than this: 0.17-0.31 for a ring
30 degrees or less above a bottle, 0.48-0.97 for the cameras over this package's patches
(the point-lit dome's 0.48 cost it 6 s at 0.5)."""
RETURN_ROUNDS = 3
"""Most ladders refitted with rejected rays that came back (each from the fit before). More
bring back the last true highlights on some clean free-form seeds (1 and 11: one each, 11
degrees off after three), but they also let a lost bottle's blob under lamps (5.3 h off)
bend to the highlights it took back until it looked supported."""
TRIALS = 3
"""Most ladders :meth:`ImplicitStart._trial_return` fits: each tries back the rays the one
before met (beside each other) by themselves."""
TRIAL_DEG = 3.0
"""A trial of the rejected rays is made only from a fit whose median miss of the kept rays'
normals is at most this (degrees): one that meets them within noise, so that the median's
change is the trial's. The catalogue's fits where one is made: 0.1-1.1 degrees. The lost
bottle's blob under lamps misses them by 15 (median): the trial's extra ladder bent it on to
6, and it looked supported 5.3 voxels off. The cross-validation passes are made only from
such a fit too."""
TRIAL_FLOOR_DEG = 0.1
"""A full-weight trial whose every ray stays may grow the kept median by this much (degrees)
where the median's standard error is smaller. Clean fits meet the kept normals within
0.1-0.4 degrees (median), and a median that small has an error of 0.02 while the refit's
path moves it by more: the point-lit dome, seed 500, clean, had 3 true rays rejected by the
first robust pass, met within 1.1 degrees when tried back, the kept median 0.113 -> 0.136
(error 0.018); refused, the dome was 0.22 h from the truth, taken 0.11. The foresight check
(:meth:`ImplicitStart._foreseen`) still guards the trial, but not against false highlights
that foresee each other and cost the rest nothing: the dome at a quarter false, seed 6,
takes back two side by side (the kept rays' misses move by 0.006 degrees, paired median),
0.15 -> 0.14 h from the truth."""
HIT_SLACK_VOXELS = 0.1
"""A lit surface of revolution refitted without the rays it half meets is taken only if the
met rays' own hits (where their normal lines meet the axis) lie no farther from it than from
the shape before, by the 90th percentile of their distances, give or take this many voxels
(their spread on clean scenes: 0.02-0.03). Bottle-lamps seed 43 with 0.5 px of noise: the
refit left out a true highlight low on the body, bulged it 1.7 voxels between the points,
and the met rays' hits moved from 0.65 to 1.34 voxels (0.51 h from the truth end to end,
0.11 with the shape before); where the refit was right (seeds 8 and 46 at a quarter false,
24 and 55 at a tenth, 24 clean and with noise) they stayed or came closer."""
SURROUND_STEPS = 1000
"""Perceptron steps :func:`surrounds` takes before it solves its linear program."""


def median_error(values: np.ndarray) -> float:
    """The standard error of the median of ``values``: ``1.2533 sigma / sqrt(n)``.

    ``sigma`` is the robust standard deviation (1.4826 times the median absolute deviation);
    ``1.2533 = sqrt(pi / 2)`` is the median's asymptotic error against the mean's for normal
    data. Zero for no values.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    if len(x) == 0:
        return 0.0
    return math.sqrt(math.pi / 2.0) * Q.robust_sigma(x - np.median(x)) / math.sqrt(len(x))


def _half_met(residual: np.ndarray) -> np.ndarray:
    """Which normal misses (degrees) are neither met within noise nor clearly false.

    Those between QUADRIC_DEG and REJECT_DEG.
    """
    return (residual > QUADRIC_DEG) & (residual <= REJECT_DEG)


def _suffices(met: np.ndarray, residual: np.ndarray) -> bool:
    """Whether rays ``met`` within noise make a shape the start (its points aside).

    QUADRIC_SHARE of them must be met, and no more than QUADRIC_AMBIGUOUS of the rest missed
    by at most REJECT_DEG (``residual``, degrees: false highlights lie further off).
    """
    ambiguous = ~met & (residual <= REJECT_DEG)
    return bool(np.mean(met) >= QUADRIC_SHARE and np.mean(ambiguous) <= QUADRIC_AMBIGUOUS)


def _noise_allowance(pixels: np.ndarray) -> float:
    """The pixels a shape judged the second time may need its highlights moved (NOISE_SPREAD).

    ``pixels``: the judged rays' pixel misses (infinite where no move meets the normal). The
    noise's sigma is estimated from their median (Rayleigh's, ``sigma sqrt(2 ln 2)``); false
    highlights raise it only as they raise the median.
    """
    median = float(np.median(pixels)) if len(pixels) else 0.0
    sigma = median / math.sqrt(2.0 * math.log(2.0))
    return float(np.clip(NOISE_SPREAD * sigma, PIXEL_NOISE, PIXEL_WIDEST))


def _unit_rows(v: np.ndarray) -> np.ndarray:
    """The rows of ``v`` ``(N, 3)`` at unit length (a zero row stays zero)."""
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


def _median_miss(residual: np.ndarray, inside: np.ndarray) -> float:
    """The median of ``residual`` over the rays ``inside``; infinite when there are none."""
    return float(np.median(residual[inside])) if inside.any() else math.inf


def level_ladder(resolution: int) -> list[int]:
    """Resolutions of the coarse-to-fine ladder: 16, 32, ... below ``resolution``, then it."""
    levels = []
    r = COARSEST
    while r < resolution:
        levels.append(r)
        r *= 2
    levels.append(resolution)
    return levels


def _robust_levels(ladder: list[int]) -> list[int]:
    """The levels of the robust passes: up to ROBUST_TOP cells, else the coarsest.

    Cross-validation and the full-weight trial's foresight fit the last of them.
    """
    return [r for r in ladder if r <= ROBUST_TOP] or ladder[:1]


def ray_convergence(origins: np.ndarray, dirs: np.ndarray) -> np.ndarray | None:
    """Least-squares point nearest to all rays (robust: rays far from it are down-weighted).

    Returns ``None`` when the rays are (nearly) parallel.
    """
    if len(origins) < 2:
        return None
    w = np.ones(len(origins))
    x = None
    for _ in range(5):
        proj = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]
        A = np.einsum("i,ijk->jk", w, proj)
        b = np.einsum("i,ijk,ik->j", w, proj, origins)
        if np.linalg.cond(A) > 1e8:
            return x
        x = np.linalg.solve(A, b)
        d = np.linalg.norm(np.einsum("ijk,ik->ij", proj, x[None] - origins), axis=1)
        s = max(Q.robust_sigma(d), 1e-12)
        w = 1.0 / (1.0 + (d / (2.0 * s)) ** 2)
    return x


def camera_ring(centres: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The axis (a point, a unit direction) of the ring the camera centres stand on, or None.

    The normal of their best-fit plane through their mean (:func:`best_fit_plane`); ``None``
    with fewer than three distinct centres or when they lie on a line (no ring).
    """
    mean, axes = best_fit_plane(np.unique(np.asarray(centres, dtype=np.float64)
                                          .reshape(-1, 3), axis=0))
    return None if axes is None else (mean, axes[2])


def surrounds(directions: np.ndarray) -> bool:
    """Whether unit ``directions`` ``(K, 3)`` leave no open half-space holding them all.

    Cameras seen from the rays' convergence point in such directions stand all around it. A
    linear feasibility problem: one side when some ``m`` has ``u . m >= 1`` for every
    direction ``u`` (a perceptron's ``m``, or else scipy's HiGHS decides). The mean
    direction is no such test: a camera a little below the horizon of a patch seen from above
    would call it surrounded.
    """
    u = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if len(u) == 0:
        return False
    # a perceptron first: it finds a half-space holding them all within 1 / margin^2 steps
    # when there is one (a scene seen from one side), and then the linear program is not
    # needed (importing scipy.optimize costs 0.3-0.5 s of a run)
    m = u.sum(axis=0)
    for _ in range(SURROUND_STEPS):
        s = u @ m
        worst = int(np.argmin(s))
        if s[worst] > 1e-9 * max(float(np.linalg.norm(m)), 1e-300):
            return False
        m = m + u[worst]
    from scipy.optimize import linprog

    fit = linprog(np.zeros(3), A_ub=-u, b_ub=-np.ones(len(u)), bounds=[(None, None)] * 3,
                  method="highs")
    return fit.status == 2  # infeasible: no half-space holds them


@dataclass
class Guess:
    """A first guess: a sphere (closed) or a plane (open), in world units."""

    kind: str
    centre: np.ndarray
    radius: float = 0.0
    normal: np.ndarray | None = None
    convergence: np.ndarray | None = None
    """The point nearest to the rays (or the points' mean), whichever the kind."""
    lean: float = 0.0
    """The length of the mean of the directions from the convergence to the cameras, when a
    half-space holds them: near 1 when they crowd over the data, small when they stand in
    rings round it."""


def _met(residual: np.ndarray) -> float:
    """The share of the rays whose normals a fit meets within QUADRIC_DEG (0 for no rays)."""
    return float(np.mean(residual <= QUADRIC_DEG)) if len(residual) else 0.0


def box_frame(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    """The quadrics' frame in the box ``[lo, hi]``: its centre and half its longest side."""
    return 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo))


def points_ellipsoid(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> Q.Quadric | None:
    """The ellipsoid of the points' spread: their covariance's, through them (median).

    In the frame of the box ``[lo, hi]``; ``None`` for fewer than four points. The covariance
    gets a thousandth of its trace on each axis, so that points in a plane still give one.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 4:
        return None
    frame, scale = box_frame(lo, hi)
    y = (pts - frame) / scale
    m = y.mean(axis=0)
    cov = np.cov((y - m).T, bias=True)
    cov += 1e-3 * np.trace(cov) * np.eye(3)
    M = np.linalg.inv(cov)
    M /= float(np.median(np.einsum("ij,jk,ik->i", y - m, M, y - m)))
    b = -2.0 * M @ m
    coeffs = np.array([M[0, 0], M[1, 1], M[2, 2], M[0, 1], M[0, 2], M[1, 2], *b,
                       float(m @ M @ m) - 1.0])
    return Q.Quadric(coeffs, frame, scale)


def columns(normal: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, count: int = COLUMNS
            ) -> tuple[np.ndarray, np.ndarray]:
    """Lines along ``-normal`` that sweep the box ``[lo, hi]`` (origins outside it, directions).

    ``count`` by ``count`` lines, evenly spread over the box's shadow on the plane across
    ``normal``.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    e1, e2 = plane_frame(n)[:2]
    centre = 0.5 * (lo + hi)
    reach = 0.5 * float(np.linalg.norm(hi - lo))
    s = np.linspace(-reach, reach, count)
    u, v = (a.ravel() for a in np.meshgrid(s, s, indexing="ij"))
    origins = centre + 2.0 * reach * n + u[:, None] * e1 + v[:, None] * e2
    return origins, np.tile(-n, (len(origins), 1))


def first_guess(scene, grid: Grid, plane: tuple[np.ndarray, np.ndarray]) -> Guess:
    """Choose the first guess from where the cameras stand.

    Args:
        scene: The scene.
        grid: The grid to solve on.
        plane: The paper's plane ``(point, normal)`` for the open case.
    """
    origins, dirs = scene.rays()
    centres = scene.camera_centres()
    used = np.unique(scene.spec_camera) if scene.num_specularities else np.arange(len(centres))
    lo, hi = grid.origin, grid.upper
    c = ray_convergence(origins, dirs) if len(origins) >= 2 else None
    if c is None or not np.all((c > lo) & (c < hi)):
        c = scene.points.mean(axis=0) if scene.num_points else 0.5 * (lo + hi)
    u = centres[used] - c
    u = _unit_rows(u)
    if not surrounds(u):
        return Guess("plane", np.asarray(plane[0], float), normal=np.asarray(plane[1], float),
                     convergence=c, lean=float(np.linalg.norm(u.mean(axis=0))))
    return sphere_guess(scene, grid, c)


def sphere_guess(scene, grid: Grid, c: np.ndarray) -> Guess:
    """A sphere about ``c`` through the points (their median distance), inside the grid."""
    lo, hi = grid.origin, grid.upper
    room = float(np.min(np.minimum(c - lo, hi - c)))
    if scene.num_points:
        radius = float(np.median(np.linalg.norm(scene.points - c, axis=1)))
    else:
        radius = 0.5 * room
    radius = min(max(radius, 2.0 * grid.spacing), max(room - grid.spacing, 2.0 * grid.spacing))
    return Guess("sphere", c, radius=radius, convergence=c)


@dataclass
class FitReport:
    """What the implicit start did.

    Attributes:
        levels: Resolution of each level of the ladder.
        rounds: Fit rounds run on each level.
        weights: Final robust weight of each ray, ``(M,)`` (0: rejected).
        residual_deg: Final angle between each ray's normal and ``grad f`` at its anchor.
        rejected: Indices of the rays rejected as inconsistent with the others.
        guess: The first guess's kind (``"sphere"`` or ``"plane"``).
        cg_iterations: Conjugate-gradient iterations of each fit.
        pockets: Sealed pockets of the grid fit removed (:func:`fill_pockets`).
        shape: What the start is: ``"quadric"``, ``"torus"``, ``"revolution"`` (a surface of
            revolution), ``"grid"`` (the grid fit) or ``"guess"`` (too little data).
        prior: What the grid fit smooths about: ``"quadric"``, ``"torus"`` or
            ``"revolution"`` (``None`` when the start is no grid fit).
        distance: Whether the field written is already a distance near its zero set (the
            quadric's first-order distance ``q / |grad q|``, exact to second order there), so
            that the flow can start from it without a redistance.
    """

    levels: list[int]
    rounds: list[int]
    weights: np.ndarray
    residual_deg: np.ndarray
    rejected: np.ndarray
    guess: str
    cg_iterations: list[int] = field(default_factory=list)
    distance: bool = False
    pockets: int = 0
    shape: str = "grid"
    prior: str | None = "quadric"


_THIRD_DIAGONAL: dict[str, float] = {}
_PRIOR_NAMES = {T.Torus: "torus", R.SurfaceOfRevolution: "revolution"}


def _better_fit(judged: tuple[tuple[int, float], np.ndarray | None],
                other: tuple[tuple[int, float], np.ndarray | None]) -> bool:
    """Whether a grid fit beats ``other``, a fit about another prior.

    Each is ``(score, misses)``: :meth:`ImplicitStart._fit_score`, and the points' distances
    from the fits made without each (``None`` with too few points). The points decide when
    their median distances are PRIOR_POINTS_RATIO apart; otherwise the larger score wins.
    """
    (score, misses), (other_score, other_misses) = judged, other
    if misses is not None and other_misses is not None:
        mine, theirs = np.median(misses), np.median(other_misses)
        if max(mine, theirs) > PRIOR_POINTS_RATIO * min(mine, theirs):
            return mine < theirs
    return score > other_score


def _third_diagonal(device) -> float:
    """The third-order energy's diagonal at an interior node, ``|G D e|^2`` (computed once).

    The smooth operator of a small level, weights 0 and 1, applied to a unit spike.
    """
    device = wp.get_device(device)
    key = str(device)
    if key not in _THIRD_DIAGONAL:
        n = 9
        level = _Level(Grid(origin=np.zeros(3), spacing=1.0, shape=(n, n, n)), device,
                       smoothness=0.0, third=1.0 / (n - 1))  # lam3 = third * (n - 1) = 1
        spike = np.zeros((n, n, n), dtype=np.float32)
        spike[n // 2, n // 2, n // 2] = 1.0
        wp.copy(level.p, wp.array(spike, dtype=float, device=device))
        level._smoothness(level.p, level.ap, 0.0)
        _THIRD_DIAGONAL[key] = float(level.ap.numpy()[n // 2, n // 2, n // 2])
    return _THIRD_DIAGONAL[key]


class _Level:
    """The device arrays of one level of the ladder and its fit."""

    def __init__(self, grid: Grid, device, *, smoothness: float = SMOOTHNESS,
                 third: float = 0.0) -> None:
        self.grid = grid
        self.device = device
        shape = grid.shape
        self.count = grid.size
        # The fit works in this level's voxels: node (i, j, k) at (i, j, k), f in voxels, so
        # the arithmetic is the same whatever the scene's units.
        self.origin = wp.vec3(0.0, 0.0, 0.0)
        self.h = 1.0
        self.world_origin = np.asarray(grid.origin, dtype=np.float64)
        self.world_h = float(grid.spacing)
        d = device
        self.f = wp.zeros(shape, dtype=float, device=d)
        self.prev = wp.zeros(shape, dtype=float, device=d)
        self.rhs = wp.zeros(shape, dtype=float, device=d)
        self.diag = wp.zeros(shape, dtype=float, device=d)
        self.ap = wp.zeros(shape, dtype=float, device=d)
        self.r = wp.zeros(shape, dtype=float, device=d)
        self.p = wp.zeros(shape, dtype=float, device=d)
        self.inv_diag = wp.zeros(shape, dtype=float, device=d)
        self.second = wp.zeros(shape, dtype=wp.vec3, device=d)
        self.mixed = wp.zeros(shape, dtype=wp.vec3, device=d)
        self.scalars = wp.zeros(4, dtype=wp.float64, device=d)
        # the Hessian energy per unit of the domain's length: lam = SMOOTHNESS * h / L
        self.lam = smoothness / float(max(grid.shape) - 1)
        # the third-order energy per unit of the domain's length: lam3 = THIRD * L / h
        self.lam3 = third * float(max(grid.shape) - 1)
        self.eps = PROXIMITY
        if self.lam3 > 0.0:
            self.second3 = wp.zeros(shape, dtype=wp.vec3, device=d)
            self.mixed3 = wp.zeros(shape, dtype=wp.vec3, device=d)
        self.prior_term = wp.zeros(shape, dtype=float, device=d)
        self._flat: dict[int, wp.array] = {}

    def to_grid(self, x: np.ndarray) -> np.ndarray:
        """World points in this level's voxels."""
        return (np.asarray(x, dtype=np.float64) - self.world_origin) / self.world_h

    def flat(self, a: wp.array) -> wp.array:
        """``a`` as one dimension (the view is made once per array)."""
        view = self._flat.get(a.ptr)
        if view is None:
            view = self._flat[a.ptr] = a.reshape((self.count,))
        return view

    def apply(self, x: wp.array, out: wp.array, grads, values) -> None:
        """``out = A x``."""
        d = self.device
        self._smoothness(x, out, self.eps)
        xs, ws = grads
        if xs.shape[0]:
            wp.launch(K.gradient_apply, dim=xs.shape[0], inputs=[x, self.origin, self.h, xs, ws],
                      outputs=[out], device=d)
        ys, vw = values
        if ys.shape[0]:
            wp.launch(K.value_apply, dim=ys.shape[0], inputs=[x, self.origin, self.h, ys, vw],
                      outputs=[out], device=d)

    def _smoothness(self, x: wp.array, out: wp.array, eps: float) -> None:
        """``out = (lam D^T W D + lam3 D^T W G^T G D + eps) x``: the smooth part of ``A``."""
        self._slabs(K.hessian_terms, [x, self.second, self.mixed])
        if self.lam3 > 0.0:
            self._slabs(K.third_terms, [self.second, self.mixed, self.lam, self.lam3,
                                        self.second3, self.mixed3])
            self._slabs(K.hessian_adjoint, [self.second3, self.mixed3, x, 1.0, eps, out])
        else:
            self._slabs(K.hessian_adjoint, [self.second, self.mixed, x, self.lam, eps, out])

    def _slabs(self, kernel: wp.Kernel, args: list) -> None:
        """Launch a stencil over the grid whose first argument is ``i0``.

        On the CPU two threads take a slab of ``i`` each (one launch while a graph is captured).
        """
        shape = self.grid.shape

        def launch(first: int, count: int, _half: int) -> None:
            wp.launch(kernel, dim=(count, shape[1], shape[2]), inputs=[first, *args],
                      device=self.device)

        launch_halves(launch, shape[0], self.device, nodes=self.count)

    def set_prior(self, prior: wp.array) -> None:
        """Make the smoothness act on ``f - prior``: store ``lam D^T W D prior``."""
        d = self.device
        self.prior_term = wp.zeros(self.grid.shape, dtype=float, device=d)
        self._smoothness(prior, self.prior_term, 0.0)

    def solve(self, grads, normals, values, iterations: int) -> int:
        """Fit ``f`` (started from its current values) to the samples; CG iterations run."""
        d = self.device
        shape = self.grid.shape
        wp.copy(self.prev, self.f)
        # rhs and diagonal: proximity + smoothness (about the prior), then the data terms
        wp.launch(K.proximity_rhs, dim=shape, inputs=[self.prev, self.eps, self.prior_term],
                  outputs=[self.rhs], device=d)
        wp.launch(K.hessian_diagonal, dim=shape,
                  inputs=[wp.vec3i(*shape), self.lam,
                          self.eps + self.lam3 * _third_diagonal(self.device)],
                  outputs=[self.diag], device=d)
        xs, ws = grads
        if xs.shape[0]:
            wp.launch(K.gradient_rhs, dim=xs.shape[0],
                      inputs=[self.f, self.origin, self.h, xs, ws, normals],
                      outputs=[self.rhs, self.diag], device=d)
        ys, vw = values
        if ys.shape[0]:
            wp.launch(K.value_diagonal, dim=ys.shape[0],
                      inputs=[self.f, self.origin, self.h, ys, vw], outputs=[self.diag], device=d)
        n = self.count
        chunks = (n + K.REDUCE_CHUNK - 1) // K.REDUCE_CHUNK
        wp.launch(K.invert, dim=n, inputs=[self.flat(self.diag), n],
                  outputs=[self.flat(self.inv_diag)], device=d)
        self.apply(self.f, self.ap, grads, values)
        self.scalars.zero_()
        wp.launch(K.cg_start, dim=chunks,
                  inputs=[self.flat(self.rhs), self.flat(self.ap), self.flat(self.inv_diag), n],
                  outputs=[self.flat(self.r), self.flat(self.p), self.scalars], device=d)
        rr0 = float(self.scalars.numpy()[K.CG_SLOTS["rr"]])
        if not rr0 > 0.0:
            return 0
        done = 0
        graph = None
        while done < iterations:
            block = min(CG_BLOCK, iterations - done)
            if block == CG_BLOCK and self.count < GRAPH_NODES:
                # a block of iterations as one Warp graph: replaying it costs a fraction of
                # the launches' own overhead, which dominates on the coarse levels
                if graph is None:
                    with wp.ScopedCapture(device=d) as capture:
                        self._cg_iterations(block, grads, values)
                    graph = capture.graph
                wp.capture_launch(graph)
            else:
                self._cg_iterations(block, grads, values)
            done += block
            rr = float(self.scalars.numpy()[K.CG_SLOTS["rr"]])
            if rr <= (CG_TOLERANCE**2) * rr0:
                break
        return done

    def _cg_iterations(self, count: int, grads, values) -> None:
        """Launch ``count`` Jacobi-preconditioned CG iterations (scalars on the device)."""
        d = self.device
        n = self.count
        chunks = (n + K.REDUCE_CHUNK - 1) // K.REDUCE_CHUNK
        for _ in range(count):
            wp.launch(K.cg_clear, dim=1, inputs=[self.scalars], device=d)
            self.apply(self.p, self.ap, grads, values)
            wp.launch(K.cg_dot, dim=chunks, inputs=[self.flat(self.p), self.flat(self.ap), n],
                      outputs=[self.scalars], device=d)
            wp.launch(K.cg_step, dim=chunks,
                      inputs=[self.flat(self.p), self.flat(self.ap), self.flat(self.inv_diag), n,
                              self.scalars],
                      outputs=[self.flat(self.f), self.flat(self.r)], device=d)
            wp.launch(K.cg_direction, dim=n,
                      inputs=[self.flat(self.r), self.flat(self.inv_diag), n, self.scalars],
                      outputs=[self.flat(self.p)], device=d)
            wp.launch(K.cg_shift, dim=1, inputs=[self.scalars], device=d)


class ImplicitStart:
    """Fit the implicit start coarse to fine and hand back the level set on the final grid.

    Args:
        scene: The scene.
        grid: The requested grid.
        device: The Warp device.
        plane: The paper's plane ``(point, normal)`` (the first guess for one-sided views).
        progress: Called with a few words as each stage begins (or ``None``).
    """

    def __init__(self, scene, grid: Grid, device, plane, *,
                 progress: Callable[[str], None] | None = None) -> None:
        self.progress = progress
        self.scene = scene
        self.grid = grid
        self.device = device
        self.plane = plane
        m = scene.num_specularities
        self.m = m
        self.anchor = wp.zeros(m, dtype=wp.vec3, device=device)
        self.kind = wp.zeros(m, dtype=int, device=device)
        self.normals = wp.zeros(m, dtype=wp.vec3, device=device)
        self.grad = wp.zeros(m, dtype=wp.vec3, device=device)
        self.weights = np.ones(m)
        self.residual = np.zeros(m)
        self.excluded = np.zeros(m, dtype=bool)
        self.tried = np.zeros(m, dtype=bool)
        """Rays tried back (:meth:`_trial_return`): full weight in the fits while they are."""
        self.point_weights = np.full(scene.num_points, POINT_WEIGHT)
        """The grid fit's weight of each point (:meth:`_noisy_points_grid`)."""
        origins, dirs = scene.rays()
        codes, vectors = scene.ray_lights()
        self._rays = (origins, dirs, codes, vectors)
        self._level_rays = None
        self._rays_level: _Level | None = None  # the level _level_rays are in the voxels of
        self.torus: T.Torus | None = None
        """The ring torus taken as the start, when one was."""
        self.revolution: R.SurfaceOfRevolution | None = None
        """The surface of revolution taken as the start, when one was."""
        self.prior: T.Torus | R.SurfaceOfRevolution | None = None
        """The closed-form shape the grid fit smooths about (``None``: the quadric)."""
        self._best: tuple[float, T.Torus | R.SurfaceOfRevolution] | None = None
        self._allowance = PIXEL_MET
        """Pixels a highlight may need to move for a closed-form shape to meet its normal and
        the ray count as met (PIXEL_MET, then PIXEL_NOISE when no shape was the start)."""
        self._noisier = False
        """Whether some ray would be met within PIXEL_NOISE pixels but not PIXEL_MET."""

    def run(self, out: wp.array) -> FitReport:
        """Fit, and write the fitted function (not yet a signed distance) into ``out``."""
        guess = first_guess(self.scene, self.grid, self.plane)
        self._one_side = guess.kind == "plane"
        self._around = guess.kind == "sphere"
        lo, hi = self.grid.origin, self.grid.upper
        frame, scale = box_frame(lo, hi)
        if guess.kind == "sphere":
            initial = Q.sphere(guess.centre, guess.radius, frame_centre=frame, scale=scale)
        else:
            initial = Q.plane(guess.centre, guess.normal, frame_centre=frame, scale=scale)
        # a sphere about the rays' convergence: the closed shapes (a torus, a surface of
        # revolution) are tried from it, seen from one side too, since cameras walked round
        # an object at one height above it lie in a half-space yet see every side of it
        ball = guess if guess.kind == "sphere" else replace(
            sphere_guess(self.scene, self.grid, guess.convergence), lean=guess.lean)
        rounds, cg = [], []
        ladder: list[int] = []
        pockets = 0
        # the closed-form shapes, judged with PIXEL_MET as the highlights' noise, then, when
        # none is the start and some ray would be met within PIXEL_NOISE, with that
        self._allowance, self._noisier = PIXEL_MET, False
        shape = self._closed_form(initial, ball, guess.kind == "plane", out)
        if shape == "grid" and self._noisier:
            self._allowance = PIXEL_NOISE
            shape = self._closed_form(initial, ball, guess.kind == "plane", out)
        feature = None
        if shape == "quadric":
            # a quadric start that lets some highlights go may have cut off a feature no
            # quadric has (a bump): the grid fit about it when a fit without them meets them
            ladder = level_ladder(max(self.grid.shape) - 1)
            feature = self._feature_fit(ladder, rounds, cg)
            if feature is None:
                ladder, rounds, cg = [], [], []
            else:
                shape = "grid"
        if feature is not None:
            pockets = self._take_fit(feature, out)
        elif shape == "grid":
            # a torus or a surface of revolution that meets more normals than the quadric
            # (shares of every ray, 180 degrees off where a ray misses the shape) but not
            # enough to be the start may be a better prior for the grid fit; it is a closed
            # object or a tube, so only its cavities are sealed pockets. Whether it is better
            # is decided by the fits themselves (:meth:`_fit_score`): a closed blob seen all
            # around is met by a tube through two of its bumps more often than by the quadric,
            # but the grid fit about the tube stays open at its ends
            shaped = self._best is not None and self._best[0] > _met(self.residual)
            if guess.kind == "plane" and max(
                    self.quadric.sheets_crossed(*self.scene.rays(), lo, hi),
                    self.quadric.sheets_crossed(*columns(guess.normal, lo, hi), lo, hi)) > 1:
                # seen from one side, a surface is crossed once by each ray, and once by each
                # line along the plane's normal; a general quadric crossed twice in the domain
                # has a second sheet there, which the fit would follow (a fold, or a sheet
                # that no ray sees), so the prior is a quadratic height field over the plane
                # instead (one sheet)
                self.quadric, _, _ = Q.fit_quadric(
                    self.scene, initial, lo=lo, hi=hi, voxel=self.grid.spacing,
                    frame=plane_frame(guess.normal))
            ladder = level_ladder(max(self.grid.shape) - 1)
            one_side = self._one_side
            best = None
            for prior in ([self._best[1], None] if shaped else [None]):
                self.prior = prior
                self._one_side = one_side and prior is None
                if shaped:
                    name = _PRIOR_NAMES.get(type(prior), "quadric")
                    self._say(f"the grid fit about the {name}")
                level, misses = self._grid_fit(ladder, rounds, cg)
                judged = (self._fit_score(level), misses)
                if best is not None and not _better_fit(judged, best[0]):
                    continue
                pockets = self._take_fit(level, out)
                best = (judged, prior, self._one_side, self.weights.copy(),
                        self.residual.copy(), self.excluded.copy())
                # free the fine level's arrays before the next fit allocates its own
                level = self._rays_level = None
            _, self.prior, self._one_side, self.weights, self.residual, self.excluded = best
        rejected = np.flatnonzero(self.weights == 0.0)
        return FitReport(levels=ladder, rounds=rounds, weights=self.weights.copy(),
                         residual_deg=self.residual.copy(), rejected=rejected, guess=guess.kind,
                         cg_iterations=cg, distance=not ladder, pockets=pockets, shape=shape,
                         prior=(_PRIOR_NAMES.get(type(self.prior), "quadric")
                                if shape == "grid" else None))

    def _closed_form(self, initial: Q.Quadric, ball: Guess, plane: bool, out: wp.array) -> str:
        """Fit the closed-form shapes; write the first that is the start by itself into ``out``.

        The quadric fitted to every ray (from ``initial``, and from ``ball``: a sphere about
        the rays' convergence), a ring torus, a surface of revolution, then quadrics fitted to
        subsets of the rays. Returns the shape taken (``"quadric"``, ``"torus"``,
        ``"revolution"``), ``"guess"`` when too little data enters the domain to fit anything,
        or ``"grid"`` when none is the start. ``plane``: the first guess is a plane (seen
        from one side).
        """
        lo, hi = self.grid.origin, self.grid.upper
        self.torus = self.revolution = self.prior = self._best = None
        self._say(f"a quadric fitted to {self.m} rays and {self.scene.num_points} points"
                  + ("" if self._allowance == PIXEL_MET else
                     f", again with up to {PIXEL_NOISE:g} px of noise on the highlights"))
        quad, self.weights, self.residual = self._fit_quadric(initial, ball, plane=plane)
        self.quadric = quad
        _, _, enters = quad.intersect(*self.scene.rays(), lo, hi)
        if int(enters.sum()) + self.scene.num_points < MIN_CONSTRAINTS:
            # too little data in the domain to fit anything: the guess stands, and the
            # verdict will say that the data does not support it
            self.quadric = initial
            self._quadric_field(self.grid, out)
            self.weights = enters.astype(float)
            return "guess"
        if (met := self._quadric_met(enters)) is not None:
            self._quadric_field(self.grid, out)
            self._keep_met(met)
            return "quadric"
        if (torus := self._torus(ball)) is not None:
            self.torus = torus
            self._torus_field(torus, out)
            return "torus"
        revolution = self._revolution(ball)
        if revolution is None:
            revolution = self._best_revolution_by_noise()
        if revolution is not None:
            self.revolution = revolution
            self._revolution_field(revolution, out)
            return "revolution"
        if (found := self._consensus_quadric(self._wide_sphere(ball.centre))) is not None:
            (self.quadric, self.weights, self.residual), met = found
            self._quadric_field(self.grid, out)
            self._keep_met(met)
            return "quadric"
        return "grid"

    def _take_fit(self, level: _Level, out: wp.array) -> int:
        """Write the grid fit ``level`` into ``out``, and its weights; the pockets sealed."""
        self.weights = np.where(self.excluded, 0.0, 1.0) * (self.kind.numpy() != K.ANCHOR_NONE)
        wp.launch(K.scaled_copy, dim=self.grid.shape, inputs=[level.f, level.world_h],
                  outputs=[out], device=self.device)
        return fill_pockets(out, both=self._one_side)

    def _feature_fit(self, ladder: list[int], rounds: list[int], cg: list[int]
                     ) -> _Level | None:
        """The grid fit about the quadric start when it meets a feature the quadric lets go.

        A quadric start may let go the highlights of a feature no quadric has (a bump seen by
        a few rays) as it lets go false ones: each is missed by more than REJECT_DEG. The
        ladder is fitted without them (it holds the quadric's shape), and those its fit
        meets come back (:meth:`_bring_back`): a fit made without a ray that meets it
        foresees it, which a false highlight's fit does not; no robust passes and no trial
        (a trial's fit bends to false normals). The fit is the start when at least two come
        back (a feature is seen by more than one highlight), the kept rays' median miss is
        within TRIAL_DEG, and cross-validation rejects none of the rays then kept: a false
        highlight that comes back is missed by the fits made without it. Otherwise ``None``,
        and the quadric start with its weights and residuals stands.
        """
        _, _, enters = self.quadric.intersect(*self.scene.rays(), self.grid.origin,
                                              self.grid.upper)
        let_go = enters & (self.weights == 0.0)
        if int(let_go.sum()) < 2:
            return None
        held = (self.weights.copy(), self.residual.copy())
        self._say(f"the grid fit about the quadric without the {int(let_go.sum())} highlights "
                  "it lets go")
        self.excluded = let_go.copy()
        level = self._ladder(ladder, rounds, cg)
        level = self._bring_back(level, ladder, rounds, cg, most=RETURN_ROUNDS)
        if (int((let_go & ~self.excluded).sum()) < 2 or self._kept_median(level) > TRIAL_DEG
                or self._cross_validate(level, _robust_levels(ladder)[-1])):
            self.weights, self.residual = held
            self.excluded = np.zeros(self.m, dtype=bool)
            self._rays_level = self._level_rays = None
            return None
        return level

    def _grid_fit(self, ladder: list[int], rounds: list[int], cg: list[int]
                  ) -> tuple[_Level, np.ndarray | None]:
        """The grid fit about the current prior, false highlights rejected.

        Returns the last level and the points' distances from the fits made without each
        (:meth:`_noisy_points_grid`).

        Robust passes on the coarse levels, stiff to supple: each rejects the rays whose
        normals it misses by far more than the others'; a stiff fit cannot bend to a false
        normal, and a supple one no longer feels those already gone. Then the whole ladder
        without them, and the rejected rays whose normals that fit meets after all (a stiff
        pass also misses a sharp but true bend) come back, with the ladder refitted from that
        fit (from the prior, a grazing ray back would be met where it first crossed the prior
        again, far before its true hit). Then cross-validation, on every ray kept (the true
        ones back): a coarse fit without each of them, and the rays those fits miss are
        rejected; the ladder is refitted from the fit so far, the rays the new fit meets come
        back (once), and the rest are tried back together (a true feature's rays, each
        unforeseeable from the others, make it together). The rays rejected before
        cross-validation are tried back first by themselves, from the fit made without the
        false highlights it rejected: put back together with those, the false ones are met too,
        the kept median grows, and none comes back (the free-form patch at a quarter false,
        seed 23: 7 true rays of a steep region that the robust passes rejected stayed out with
        the 12 false ones cross-validation rejected, 35 of 60 rays met, refused; tried by
        themselves 6 come back, then 3 true ones cross-validation rejected: 12 false and 1 true
        rejected in the end, 0.34 h). Only from a fit that meets the kept normals within
        noise (as for the trial): the lost bottle's blob under lamps, refitted without the rays
        it misses, looked supported.
        """
        self.excluded = np.zeros(self.m, dtype=bool)
        self.point_weights[:] = POINT_WEIGHT
        coarse = _robust_levels(ladder)
        for index, smoothness in enumerate(ROBUST_SMOOTHNESS):
            self._say(f"robust pass {index + 1} of {len(ROBUST_SMOOTHNESS)} "
                      f"(grids {', '.join(map(str, coarse))})")
            self._ladder(coarse, [], [], smoothness=smoothness, third=0.0, quiet=True)
            self.excluded |= self._outliers()
        previous = self._ladder(ladder, rounds, cg)
        previous = self._bring_back(previous, ladder, rounds, cg, most=RETURN_ROUNDS)
        previous = self._trial_return(previous, ladder, rounds, cg)
        passed = self.excluded.copy()  # the rays the robust passes and the returns left out
        if self._kept_median(previous) <= TRIAL_DEG and self._cross_validate(
                previous, coarse[-1]):
            self._say("the ladder again, without the highlights cross-validation rejects")
            previous = self._ladder(ladder, rounds, cg, quiet=True, start=previous)
            previous = self._bring_back(previous, ladder, rounds, cg, most=1)
            if (self.excluded & ~passed).any():
                previous = self._trial_return(previous, ladder, rounds, cg, among=passed)
            previous = self._trial_return(previous, ladder, rounds, cg)
        return self._noisy_points_grid(previous, ladder, rounds, cg)

    def _noisy_points_grid(self, previous: _Level, ladder: list[int], rounds: list[int],
                           cg: list[int]) -> tuple[_Level, np.ndarray | None]:
        """``previous``, or the ladder refitted from it with the points weighed as noisy.

        Each point is left out in turn from a fit of the robust levels (from the prior, the
        rays kept as they are), once with the points at POINT_WEIGHT and once at
        :data:`NOISY_GRID_POINT_WEIGHT`; when the fits at the noisy weight pass nearer to the
        points left out (the median distance) by :data:`NOISY_GRID_RATIO`, the ladder is
        refitted at that weight, and taken when it meets the kept normals closer by
        :data:`NOISY_GRID_GAIN` (the median miss).

        The rays are left anchored on the fit of the last level made; the caller anchors
        them on the fit returned (:meth:`_fit_score`). Returned beside the fit: the points'
        distances at POINT_WEIGHT (``None`` with too few points), by which fits about
        different priors are compared (:func:`_better_fit`).
        """
        if self.scene.num_points < NOISY_GRID_POINTS:
            return previous, None
        self._say(f"the points left out one at a time ({2 * self.scene.num_points} fits)")
        misses = np.abs(self._point_misses(POINT_WEIGHT, ladder))
        held = np.median(misses)
        loose = np.median(np.abs(self._point_misses(NOISY_GRID_POINT_WEIGHT, ladder)))
        if loose < NOISY_GRID_RATIO * held:
            missed = self._kept_median(previous)
            self._say("the ladder again, the points weighed as noisy")
            self.point_weights[:] = NOISY_GRID_POINT_WEIGHT
            refit = self._ladder(ladder, rounds, cg, quiet=True, start=previous)
            if self._kept_median(refit) < NOISY_GRID_GAIN * missed:
                return refit, misses
            self.point_weights[:] = POINT_WEIGHT
        return previous, misses

    def _point_misses(self, weight: float, ladder: list[int]) -> np.ndarray:
        """Each point's distance (voxels of the grid) from a fit made without it.

        The fits are of the robust levels, from the prior, the other points at ``weight``.
        """
        points = self.scene.points.reshape(-1, 3)
        misses = np.zeros(len(points))
        self.point_weights[:] = weight
        for i in range(len(points)):
            self.point_weights[i] = 0.0
            level = self._ladder(_robust_levels(ladder), [], [], quiet=True)
            self.point_weights[i] = weight
            value = sample_trilinear(level.f.numpy(), level.grid, points[i:i + 1])[0]
            misses[i] = value * level.world_h / self.grid.spacing
        self.point_weights[:] = POINT_WEIGHT
        return misses

    def _fit_score(self, level: _Level) -> tuple[int, float]:
        """How well a grid fit explains the rays, larger is better (anchors them on it).

        The kept rays that cross its zero set where it meets their normals within
        :data:`RETURN_DEG`, then the negated median miss of the kept normals (degrees). Two
        fits about different priors are compared by it, unless their points tell them apart
        (:func:`_better_fit`): the data decides. Crossings alone do not tell: a fat blob
        that every ray crosses, missing half the normals by 15-90 degrees, would beat the
        bottle that meets all it keeps within 3.

        Medians within :data:`QUADRIC_DEG` (noise) tie, and a tie keeps the fit about the
        shaped prior (tried first): it explained more normals by itself. A bottle seen by
        21 flash-lit rays and 3 points (seed 1 of ``bottle`` with half its highlights): both
        fits met all 21 normals, about the surface of revolution with a median miss of 0.58
        degrees, about the quadric 0.40, and the quadric's was taken, 1.34 h from the
        truth; the revolution's is 0.94 h.
        """
        median = self._kept_median(level)
        met = (~self.excluded & (self.kind.numpy() == K.ANCHOR_CROSSING)
               & (self.residual <= RETURN_DEG))
        return int(met.sum()), -max(median, QUADRIC_DEG)

    def _ladder(self, ladder: list[int], rounds: list[int], cg: list[int], *,
                smoothness: float | None = None, third: float | None = None,
                quiet: bool = False, start: _Level | None = None) -> _Level:
        """Fit on every level of the ladder, each started from the one below.

        The first level starts from the prior, or from ``start`` (a fit already made).
        """
        lo, hi = self.grid.origin, self.grid.upper
        previous: _Level | None = None
        self.weights = np.where(self.excluded, 0.0, 1.0)
        for index, res in enumerate(ladder):
            last = index == len(ladder) - 1
            grid = self.grid if res == max(self.grid.shape) - 1 else Grid.from_bounds(
                lo, hi, resolution=res)
            if not quiet:
                self._say(f"grid {res} of {', '.join(map(str, ladder))}")
            level = _Level(grid, self.device,
                           smoothness=SMOOTHNESS if smoothness is None else smoothness,
                           third=THIRD if third is None else third)
            self._use_level_rays(level)
            self._prior_field(grid, level.p, unit=grid.spacing)  # the prior, in voxels
            level.set_prior(level.p)
            below = previous if previous is not None else start
            if below is None:
                wp.copy(level.f, level.p)
            else:
                wp.launch(K.resample, dim=grid.shape,
                          inputs=[below.f, below.world_h / level.world_h],
                          outputs=[level.f], device=self.device)
            fine = last or res > FINE_ABOVE
            n_rounds = ROUNDS_FINE if fine else ROUNDS_COARSE
            for _ in range(n_rounds):
                cg.append(self._round(level, CG_ITERATIONS_FINE if fine else CG_ITERATIONS))
            rounds.append(n_rounds)
            previous = level
        return previous

    def _bring_back(self, previous: _Level, ladder: list[int], rounds: list[int],
                    cg: list[int], *, most: int) -> _Level:
        """Rejected rays that ``previous`` (fitted without them) meets come back, refitted.

        A ray comes back when its normal is met within the kept rays' threshold or
        RETURN_DEG; each time some do, the ladder is refitted from ``previous`` (at most
        ``most`` times: those back reshape the surface, and others may meet it then).
        """
        for _ in range(most):
            if not self.excluded.any():
                break
            self._anchor(previous)
            self._update_weights(previous)
            back = self.excluded & (self.residual <= max(self._threshold(), RETURN_DEG))
            if not back.any():
                break
            self.excluded &= ~back
            self._say(f"the ladder again, {int(back.sum())} rejected highlights back")
            previous = self._ladder(ladder, rounds, cg, quiet=True, start=previous)
        return previous

    def _trial_return(self, previous: _Level, ladder: list[int], rounds: list[int],
                      cg: list[int], *, among: np.ndarray | None = None) -> _Level:
        """The ladder refitted with every rejected ray back, kept if it fits the rest better.

        ``among``: a mask; only the rejected rays in it are tried back (all by default).

        A stiff pass rejects the highlights of a sharp feature that no highlight kept shows
        (a bump seen by a few rays), and a fit made without them cannot meet them either. Put
        back together, they make the feature, and the kept rays' normals are met at least as
        closely as before (:meth:`_robust_trial`). A false highlight the fit bends to makes a
        dent that its neighbours miss: the kept rays' median miss grows, and none comes back.
        The median, not the RMS: false highlights kept all along inflate an RMS, and a dent
        that meets them better hid its cost to the rest (the point-lit dome at a quarter
        false, seed 6: the RMS fell 7%, the median rose 144%). The rays the new fit still
        misses beyond :meth:`_threshold` stay out, and so does one whose hit neighbours no
        other's that would stay (:meth:`_together`): a feature's rays make it together, and a
        ray that only the fit bent to it meets is what a false highlight looks like. A trial
        whose every ray stays may move the kept median by its standard error
        (:func:`median_error`): the refit's path moves it that much (the clean free-form
        patch, seed 402: the bump's 6 rays all met within 1.2 degrees, the median 0.344 ->
        0.357, its error 0.057; refused, the bump was cut off, 0.75 h from the truth).

        When that trial takes none, the rays are tried at full weight (:meth:`_full_trial`):
        a fit without the feature misses its rays by more than the robust weights' limit,
        which drops them from its first round. The free-form patch, seed 402, a tenth false:
        of the bump's 5 true rays the passes reject 2, a trial under the robust weights met
        one and missed the other by 27 degrees, both stayed out, cross-validation then
        rejected the other 3, and the patch was 0.94 h from the truth (0.78 with the false
        highlights removed by hand); at full weight both are met within 0.8 degrees (0.31 h).
        Full weight first would take false highlights that the robust trial refuses: the
        free-form patch at a quarter false, seed 6, 0.24 -> 0.58 h. No trial is made from a
        fit that misses the kept normals by more than :data:`TRIAL_DEG` (median): one more
        ladder reshapes it anyway.
        """
        if not self.excluded.any():
            return previous
        median = self._kept_median(previous)
        live = self.kind.numpy() != K.ANCHOR_NONE
        trial = self.excluded & live
        if among is not None:
            trial &= among
        if not trial.any() or median > TRIAL_DEG:
            return previous
        before, miss_before = self.excluded.copy(), self.residual.copy()
        taken = self._robust_trial(previous, ladder, rounds, cg, trial, before, miss_before)
        if taken is None:
            taken = self._full_trial(previous, ladder, rounds, cg, trial, before, miss_before)
        if taken is None:
            self.excluded = before
            return previous
        return taken

    def _try(self, previous: _Level, ladder: list[int], rounds: list[int], cg: list[int],
             trial: np.ndarray, before: np.ndarray, *, full: bool
             ) -> tuple[_Level, np.ndarray, np.ndarray]:
        """The ladder from ``previous`` with the ``trial`` rays back (at full weight or not).

        Returns the fit, the kept rays that meet it (a mask) and the trial's rays that would
        stay: met within :meth:`_threshold`, each beside another (:meth:`_together`).
        """
        live = self.kind.numpy() != K.ANCHOR_NONE
        kept = ~before & live
        self.excluded = before & ~trial
        self._say(f"the ladder again, {int(trial.sum())} rejected highlights tried back")
        if full:
            self.tried = trial
        try:
            candidate = self._ladder(ladder, rounds, cg, quiet=True, start=previous)
        finally:
            self.tried = np.zeros(self.m, dtype=bool)
        self._anchor(candidate)
        self._update_weights(candidate)
        kept &= self.kind.numpy() != K.ANCHOR_NONE
        stay = trial & (self.residual <= self._threshold())
        # a ray alone makes no feature: only the fit bent to it meets it, as a false
        # highlight is met
        return candidate, kept, self._together(stay, kept | stay)

    def _robust_trial(self, previous: _Level, ladder: list[int], rounds: list[int],
                      cg: list[int], trial: np.ndarray, before: np.ndarray,
                      miss_before: np.ndarray) -> _Level | None:
        """The trial under the robust weights; the fit taken, or ``None`` when none is."""
        candidate, kept, stay = self._try(previous, ladder, rounds, cg, trial, before,
                                          full=False)
        if not kept.any():
            return None
        # a trial whose every ray stays is a feature, and the kept median may move by its
        # own standard error (the path of the refit); otherwise it must not grow
        every = np.array_equal(stay, trial)
        grown = float(np.median(self.residual[kept]) - np.median(miss_before[kept]))
        if grown > (median_error(miss_before[kept]) if every else 0.0) or not stay.any():
            return None
        self.excluded = before & ~stay
        if every:
            return candidate
        return self._ladder(ladder, rounds, cg, quiet=True, start=previous)

    def _full_trial(self, previous: _Level, ladder: list[int], rounds: list[int],
                    cg: list[int], trial: np.ndarray, before: np.ndarray,
                    miss_before: np.ndarray) -> _Level | None:
        """The trial at full weight; the fit taken, or ``None`` when none is.

        Those of a trial that stay are tried again by themselves (at most :data:`TRIALS`
        ladders), the others having bent the fit; a trial whose every ray stays is taken
        when the kept median grows by no more than its standard error or
        :data:`TRIAL_FLOOR_DEG`, with the rays the others foresee (:meth:`_foreseen`, at
        least two): at full weight a fit meets false highlights side by side too (the
        free-form patch at a quarter false, seed 2: two met within 2.3 and 5.6 degrees, the
        median 0.368 -> 0.401, its error 0.050; neither foreseen by the other, and taken,
        the patch was 0.32 h from the truth, not 0.18).
        """
        for _ in range(TRIALS):
            candidate, kept, stay = self._try(previous, ladder, rounds, cg, trial, before,
                                              full=True)
            if not kept.any() or not stay.any():
                return None
            if not np.array_equal(stay, trial):
                trial = stay
                continue
            grown = float(np.median(self.residual[kept]) - np.median(miss_before[kept]))
            if grown > max(median_error(miss_before[kept]), TRIAL_FLOOR_DEG):
                return None
            foreseen = self._foreseen(trial, before, candidate, ladder)
            if int(foreseen.sum()) < 2:
                return None
            self.excluded = before & ~foreseen
            if foreseen.all():
                return candidate
            # those the others do not foresee stay out, refitted from the feature made
            return self._ladder(ladder, rounds, cg, quiet=True, start=candidate)
        return None

    def _foreseen(self, trial: np.ndarray, before: np.ndarray, candidate: _Level,
                  ladder: list[int]) -> np.ndarray:
        """Those of the ``trial`` rays that a fit with the others tried and without them meets.

        Each is left out in turn from a fit of the cross-validation's level started from
        ``candidate``, the rest of the trial tried back (full weight); it is foreseen when
        that fit meets its normal within :data:`CV_DEG`. A feature's rays foresee each other;
        false highlights that a fit bent to meet one by one do not. ``before``: the rays
        rejected before the trial, which stay out. Returns a mask of all rays.
        """
        resolution = _robust_levels(ladder)[-1]
        out = trial.copy()
        for i in np.flatnonzero(trial):
            self.tried = trial.copy()
            self.tried[i] = False
            try:
                miss = self._misses_without([i], before & ~trial, candidate, resolution)
            finally:
                self.tried = np.zeros(self.m, dtype=bool)
            out[i] = miss[i] <= CV_DEG
        self.excluded = before & ~trial
        return out

    def _misses_without(self, held: np.ndarray | list[int], excluded: np.ndarray, start: _Level,
                        resolution: int) -> np.ndarray:
        """Every ray's normal miss (degrees) by a fit made without the ``held`` rays.

        The fit is of ``resolution`` cells, started from ``start``, the ``excluded`` rays out
        too (they stay excluded, with ``held``, until the caller resets them).
        """
        self.excluded = excluded.copy()
        self.excluded[held] = True
        level = self._ladder([resolution], [], [], quiet=True, start=start)
        self._anchor(level)
        self._update_weights(level)
        return self.residual

    def _together(self, rays: np.ndarray, among: np.ndarray) -> np.ndarray:
        """Those of ``rays`` (a mask) whose hits neighbour another's (a mask of all rays).

        Two hits neighbour each other when no hit of ``among`` lies inside the ball whose
        diameter joins them (the Gabriel graph of the hits): no ray between them sees the
        surface there. Hits as the rays last met a fit (:meth:`_anchor`).
        """
        index = np.flatnonzero(rays)
        out = np.zeros(self.m, dtype=bool)
        if len(index) < 2:
            return out
        anchors = self.anchor.numpy().astype(np.float64)
        others = anchors[among]
        for a, i in enumerate(index):
            for j in index[a + 1:]:
                centre = 0.5 * (anchors[i] + anchors[j])
                radius = 0.5 * np.linalg.norm(anchors[i] - anchors[j])
                inside = np.linalg.norm(others - centre, axis=1) < radius * (1.0 - 1e-9)
                if not inside.any():
                    out[i] = out[j] = True
        return out

    def _cross_validate(self, start: _Level, resolution: int) -> bool:
        """Reject the rays whose normals fits made without them miss (out of sample).

        Each of at most :data:`CV_PASSES` passes fits the level of ``resolution`` cells (the
        finest up to ROBUST_TOP) with every kept ray (the reference, from the pass before's,
        the first from ``start``), then once without each of :data:`CV_FOLDS` folds of them
        (one ray each while they are that few), from the reference and with the final fit's
        smoothness. A fold's rays are rejected when that fit misses their normals by more than
        :data:`CV_DEG`, or by more than :data:`CV_HULL_DEG` where a fit without it
        extrapolates (:meth:`_on_hull`; a corner of the hull of the hits the first pass keeps,
        and of the pass's), and an inner ray missed far beyond every other
        (:meth:`_lone_miss`), or, seen all around, beyond the others' spread
        (:meth:`_spread_miss`). At most :data:`CV_SHARE` of the kept rays per pass,
        the worst missed first; a pass that rejects none ends them. Returns whether any ray
        was rejected.
        """
        rejected = False
        reference = start
        bounds = None  # the corners of the hull of the hits the first pass keeps
        for index in range(CV_PASSES):
            base = self.excluded.copy()
            kept = np.flatnonzero(~base)
            folds = min(CV_FOLDS, len(kept))
            if folds < 2:
                break
            self._say(f"cross-validation pass {index + 1} of {CV_PASSES} ({folds} folds, "
                      f"grid {resolution})")
            reference = self._ladder([resolution], [], [], quiet=True, start=reference)
            self._anchor(reference)  # the hits the hull is taken of
            corners = self._on_hull(kept)
            if bounds is None:
                bounds = corners
            # a ray that bounds the hits only since those beyond it were rejected keeps the
            # inner limit: a rejected ray may come back, and its region is the data's
            inner = ~(corners & bounds)
            order = np.random.default_rng(index).permutation(kept)
            miss = np.full(self.m, 180.0)
            for fold in range(folds):
                held = order[fold::folds]
                miss[held] = self._misses_without(held, base, reference, resolution)[held]
            self.excluded = base
            met = ~base & (miss < 180.0)
            over = met & (miss > np.where(inner, CV_DEG, CV_HULL_DEG))
            over |= self._lone_miss(np.where(met & inner, miss, -1.0))
            if self._around:
                over |= self._spread_miss(np.where(met, miss, -1.0))
            most = math.ceil(CV_SHARE * len(kept))
            if int(over.sum()) > most:
                worst = np.argsort(np.where(over, -miss, np.inf), kind="stable")[:most]
                over = np.zeros(self.m, dtype=bool)
                over[worst] = True
            if not over.any():
                break
            self.excluded = base | over
            rejected = True
        return rejected

    @staticmethod
    def _lone_miss(miss: np.ndarray) -> np.ndarray:
        """The ray missed by more than :data:`CV_FLOOR_DEG` and CV_GAP times any other (a mask).

        ``miss``: out-of-sample misses (degrees), negative for the rays not compared.
        """
        out = np.zeros(len(miss), dtype=bool)
        if len(miss) < 2:
            return out
        second, first = np.argsort(miss, kind="stable")[-2:]
        if miss[first] > max(CV_FLOOR_DEG, CV_GAP * miss[second]):
            out[first] = True
        return out

    @staticmethod
    def _spread_miss(miss: np.ndarray) -> np.ndarray:
        """The rays missed beyond the others' spread (a mask).

        Beyond :data:`REJECT_SIGMAS` robust standard deviations above the median miss, and
        beyond :data:`CV_FLOOR_DEG`; used seen all around (the first guess a sphere), see
        CV_GAP. ``miss``: out-of-sample misses (degrees), negative for the rays not compared.
        """
        compared = miss >= 0.0
        if int(compared.sum()) < 2:
            return np.zeros(len(miss), dtype=bool)
        centre = float(np.median(miss[compared]))
        sigma = Q.robust_sigma(miss[compared] - centre)
        return compared & (miss > max(CV_FLOOR_DEG, centre + REJECT_SIGMAS * sigma))

    def _on_hull(self, rays: np.ndarray) -> np.ndarray:
        """Which of ``rays`` a fit without them extrapolates to (a mask of all rays).

        Seen from one side: the corners of their hits' hull in the plane through the points,
        but not a corner whose nearest other hit is no farther than :data:`CV_NEAR` of the
        hits' median distance to their nearest: a fit without it is carried there from that
        hit, as it is to an inner ray from its neighbours. (The point-lit dome at a quarter
        false, seed 6: a false highlight 0.05 from a true one, at a corner of a hull that stops
        short of the patch's edge, was missed out of sample by 12.6 degrees, under the corners'
        15, and kept: 0.16 h worse than the clean scene, 0.06 rejected.) Hits on a line all
        count: across it, a fit extrapolates from any of them. Else none.
        """
        corner = np.zeros(self.m, dtype=bool)
        rays = rays[self.kind.numpy()[rays] != K.ANCHOR_NONE]
        if not self._one_side or len(rays) < 4:
            return corner
        from scipy.spatial import ConvexHull, QhullError, cKDTree

        axes = plane_frame(np.asarray(self.plane[1], dtype=np.float64))[:2]
        xy = self.anchor.numpy().astype(np.float64)[rays] @ axes.T
        try:
            hull = ConvexHull(xy).vertices
        except QhullError:  # anchors on a line: every one bounds the others
            corner[rays] = True
            return corner
        nearest = cKDTree(xy).query(xy, k=2)[0][:, 1]
        corner[rays[hull[nearest[hull] > CV_NEAR * np.median(nearest)]]] = True
        return corner

    def _kept_median(self, level: _Level) -> float:
        """Median normal miss (degrees) of the kept rays that meet ``level``'s fit (inf: none).

        Anchors the rays on it and updates their residuals and weights.
        """
        self._anchor(level)
        self._update_weights(level)
        kept = ~self.excluded & (self.kind.numpy() != K.ANCHOR_NONE)
        return float(np.median(self.residual[kept])) if kept.any() else math.inf

    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _outliers(self) -> np.ndarray:
        """Rays not yet rejected whose normal the fit misses by more than :meth:`_threshold`."""
        live = (self.kind.numpy() != K.ANCHOR_NONE) & ~self.excluded
        return live & (self.residual > self._threshold())

    def _threshold(self) -> float:
        """The largest normal miss (degrees) of a kept ray.

        REJECT_SIGMAS robust standard deviations of the kept rays' misses, at least REJECT_DEG.
        """
        live = (self.kind.numpy() != K.ANCHOR_NONE) & ~self.excluded
        if not live.any():
            return math.inf
        sigma = Q.robust_sigma(self.residual[live])
        return max(REJECT_SIGMAS * sigma, REJECT_DEG)

    def _fit_quadric(self, initial: Q.Quadric, ball: Guess, *, plane: bool
                     ) -> tuple[Q.Quadric, np.ndarray, np.ndarray]:
        """The quadric fit that meets most normals (the first of equals) of those from each start.

        The starts are ``initial`` and spheres about the rays' convergence. The alternation of
        intersection and fit settles on the quadric nearest its start, and from a start far
        inside the object it may settle on a wrong one: the first guess runs through the
        points, which on a flat object lie mostly on its faces, well inside the rim (the
        ``pebble`` scene, 0.3-0.4 thick and 2 wide, seen all around under lamps: on seeds 4 and
        6 at a quarter false, none of the 28 normals met). A sphere as wide as the domain, about
        the same centre, encloses a boxed object, and the fit from outside it meets every true
        normal there. A patch seen from one side may also be curved like a sphere seen
        from outside, so there the sphere through the points is a start too. On every other
        scene of the catalogue every start meets the same share. Of fits that meet as many,
        the one fewest rays enter from inside (:meth:`Quadric.entered_from_inside`) is taken:
        the octant, turned in a domain that holds more of its sphere, was met as well by a
        quadric from the plane (every normal within 3 degrees, the median 0.4) that 4 of its
        24 rays reached through its inside, where the spheres' fits met them exactly.

        Returns:
            The quadric, the rays' robust weights and their misses in degrees.
        """
        lo, hi = self.grid.origin, self.grid.upper
        frame, scale = box_frame(lo, hi)
        starts = [initial]
        if plane:
            starts.append(Q.sphere(ball.centre, ball.radius, frame_centre=frame, scale=scale))
        starts.append(self._wide_sphere(ball.centre))
        fits = [Q.fit_quadric(self.scene, start, lo=lo, hi=hi, voxel=self.grid.spacing)
                for start in starts]
        rays = self.scene.rays()
        return self._noisy_points_fit(max(fits, key=lambda fit: (
            _met(fit[2]), -int(fit[0].entered_from_inside(*rays, lo, hi).sum()))), rays)

    def _noisy_points_fit(self, fit: tuple[Q.Quadric, np.ndarray, np.ndarray],
                          rays: tuple[np.ndarray, np.ndarray]
                          ) -> tuple[Q.Quadric, np.ndarray, np.ndarray]:
        """``fit``, or its refit with the points weighed as noisy where that is the start.

        The refit (from ``fit``, the points at :data:`~warpspec.quadric.NOISY_POINT_WEIGHT`)
        is taken when it is the start by itself (:meth:`_quadric_met`), ``fit``'s median
        normal miss is NOISY_POINT_DEG or more, and the refit's at most NOISY_POINT_GAIN times
        it. ``rays``: the scene's (origins, directions).
        """
        if not self.scene.num_points:
            return fit
        lo, hi = self.grid.origin, self.grid.upper
        loose = Q.fit_quadric(self.scene, fit[0], lo=lo, hi=hi, voxel=self.grid.spacing,
                              point_weight=Q.NOISY_POINT_WEIGHT)
        inside = [f[0].intersect(*rays, lo, hi)[2] for f in (fit, loose)]
        if inside[1].any() and self._quadric_met(inside[1], loose) is not None:
            before, after = (_median_miss(f[2], m) for f, m in zip((fit, loose), inside,
                                                                   strict=True))
            if before >= NOISY_POINT_DEG and after <= NOISY_POINT_GAIN * before:
                return self._noisy_points_ellipsoid(loose, inside[1])
        return self._noisy_points_ellipsoid(fit, inside[0])

    def _noisy_points_ellipsoid(self, fit: tuple[Q.Quadric, np.ndarray, np.ndarray],
                                inside: np.ndarray
                                ) -> tuple[Q.Quadric, np.ndarray, np.ndarray]:
        """``fit``, or the ellipsoid refitted in pixels with the points weighed as noisy.

        When ``fit``'s quadric is an ellipsoid, it is refitted
        (:func:`warpspec.ellipsoid.refit_ellipsoid`) to the rays it meets within REJECT_DEG,
        then once more to those the refit meets so. The refit is taken when it is the start by
        itself (:meth:`_quadric_met`) and, when ``fit`` was the start, the points lie
        NOISY_POINT_RATIO times further from it than its rays pass the points with their
        normals, in pixels (the rays of the last refit), and those rays pass them
        NOISY_REFIT_GAIN times closer than with ``fit``'s ellipsoid. The pebble, points a
        voxel off per axis and half a pixel on the highlights, seeds 0, 4 and 5: no quadric
        was the start (75-82% of the normals within 3 degrees); the refit meets every normal,
        its radii and centre within 0.02 voxel of the truth. ``inside``: the rays that enter
        the domain (``fit``'s quadric's).
        """
        held = E.Ellipsoid.from_quadric(fit[0])
        if held is None or not self.scene.num_points:
            return fit
        lo, hi = self.grid.origin, self.grid.upper
        origins, dirs = self.scene.rays()
        was_start = self._quadric_met(inside, fit) is not None
        pixel = self.scene.pixel_angles()
        points = self.scene.points.reshape(-1, 3)
        residual, shape, rays = fit[2], held, None
        self._say("an ellipsoid fitted again with the points as noisy")
        for _ in range(2):
            use = inside & (residual <= REJECT_DEG)
            rays = (origins[use], dirs[use], self._asked(use), pixel[use])
            shape = E.refit_ellipsoid(shape, *rays, points, voxel=self.grid.spacing)
            if shape is None:
                return fit
            quad = shape.quadric(centre=fit[0].centre, scale=fit[0].scale)
            anchors, _, inside = quad.intersect(origins, dirs, lo, hi)
            residual = miss_deg(_unit_rows(quad.gradient(anchors)), self.scene.normals(anchors),
                                inside)
        refit = (quad, Q.robust_weights(residual, inside, limit_deg=Q.FINAL_LIMIT_DEG), residual)
        if not inside.any() or self._quadric_met(inside, refit) is None:
            return fit
        if was_start:
            misses = E.pixel_misses(shape, *rays)
            if (not self._points_noisier(shape.distance(points), float(np.median(pixel)),
                                         misses, NOISY_POINT_RATIO)
                    or not self._refit_closer(misses, E.pixel_misses(held, *rays))):
                return fit
        return refit

    @staticmethod
    def _refit_closer(refit: np.ndarray, held: np.ndarray) -> bool:
        """Whether a refit meets the rays NOISY_REFIT_GAIN times closer than the held shape.

        ``refit``, ``held``: the rays' pixel misses by each (their medians are compared).
        """
        return bool(np.median(refit) <= NOISY_REFIT_GAIN * np.median(held))

    def _points_noisier(self, distance: np.ndarray, pixel: float, misses: np.ndarray,
                        ratio: float) -> bool:
        """Whether the points lie ``ratio`` times further from a shape than its rays miss.

        Medians, both in pixels: the points' ``distance`` from the shape (world units) over a
        pixel's width (``pixel``, radians) at their depth (:func:`~.pixel_fit.point_pixels`),
        and the rays' pixel ``misses``.
        """
        points = self.scene.points.reshape(-1, 3)
        return bool(np.median(point_pixels(distance, points, self.scene.camera_centres(), pixel))
                    >= ratio * np.median(misses))

    def _wide_sphere(self, centre: np.ndarray) -> Q.Quadric:
        """A sphere about ``centre`` as wide as the domain (radius half its longest side)."""
        frame, scale = box_frame(self.grid.origin, self.grid.upper)
        return Q.sphere(centre, scale, frame_centre=frame, scale=scale)

    def _consensus_quadric(self, start: Q.Quadric
                           ) -> tuple[Q.Quadric, np.ndarray, np.ndarray] | None:
        """A quadric that is the start by itself, found from subsets of the rays.

        Tried when neither the quadric fitted to every ray, nor a torus, nor a surface of
        revolution is the start (so a torus or a bottle does not pay for it). Fits to
        CONSENSUS_RAYS random rays each (a fixed sequence: the same scene gives the same
        start), from ``start``; when one meets QUADRIC_SHARE of every ray's normal, the fit to
        the rays it meets within REJECT_DEG (robust from the first round), or that subset's fit
        when it meets more normals, is taken if it is the start by itself
        (:meth:`_quadric_met`), else the search goes on. It looks for a quadric object
        that false highlights or a poor start dragged off (a flat ellipsoid under a lamp, a
        tenth false: the fit from every start missed two grazing true normals by 6.6 and 9.0
        degrees, the one from the truth none; within 1.4 px of it, they no longer keep that
        fit from being the start, 0.021 h end to end against the subset's 0.015), not for a
        better prior of a shape that is none (a blob, seed
        2: a subset's quadric met 70% of the normals, and the grid fit about it was 0.013 h
        worse). Returns that fit and the rays it meets, or ``None`` when no subset gives one.
        """
        if self.m <= CONSENSUS_RAYS:
            return None
        lo, hi = self.grid.origin, self.grid.upper
        rng = np.random.default_rng(0)
        for _ in range(CONSENSUS_TRIALS):
            use = np.zeros(self.m, dtype=bool)
            use[rng.choice(self.m, CONSENSUS_RAYS, replace=False)] = True
            quad, _, residual = Q.fit_quadric(self.scene, start, lo=lo, hi=hi,
                                              voxel=self.grid.spacing, use=use)
            if _met(residual) < QUADRIC_SHARE:
                continue
            fit = Q.fit_quadric(self.scene, quad, lo=lo, hi=hi, voxel=self.grid.spacing,
                                robust_from=0, use=residual <= REJECT_DEG)
            # under a point light the refit can leave a grazing ray or two a few degrees off,
            # where the subset's quadric met them (pebble under a lamp, seed 1, a quarter
            # false: 18 of 26 normals met within QUADRIC_DEG against 20)
            weights = Q.robust_weights(residual, residual < 180.0, limit_deg=Q.FINAL_LIMIT_DEG)
            fits = [(f, met) for f in (fit, (quad, weights, residual))
                    if (met := self._quadric_met(f[2] < 180.0, f)) is not None]
            if fits:
                self._say("a quadric found from a subset of the highlights")
                return max(fits, key=lambda f: _met(f[0][2]))
        return None

    def _quadric_met(self, inside: np.ndarray, fit: tuple | None = None) -> np.ndarray | None:
        """The rays the quadric meets if it is the start (:meth:`_start_met`), else ``None``.

        ``inside``: the rays that enter the domain. ``fit`` (a quadric, its weights and
        residuals) is judged instead of the one taken.
        """
        quad, residual = (self.quadric, self.residual) if fit is None else (fit[0], fit[2])
        return self._start_met(quad, residual, inside,
                               quad.distance(self.scene.points.reshape(-1, 3)))

    def _keep_met(self, met: np.ndarray) -> None:
        """Set the quadric start's weights: 1 for a ray its fit kept or that it meets (else 0).

        The rays it meets (``met``, :meth:`_start_met`) include grazing true highlights that
        the fit's robust weights let go, when it is the start by their pixel misses.
        """
        self.weights = np.where((self.weights > 0.0) | met, 1.0, 0.0)

    def _start_met(self, shape, residual: np.ndarray, inside: np.ndarray,
                   point_distance: np.ndarray, *, by_noise: bool = False
                   ) -> np.ndarray | None:
        """The rays a closed-form shape meets if it is the start by itself, else ``None``.

        The shape is a quadric, a torus or a surface of revolution.

        Args:
            shape: The shape.
            residual: Its normal misses (degrees), one per ray.
            inside: The rays that meet the domain (those judged).
            point_distance: The points' distances from it (world units).
            by_noise: Judge a surface of revolution too by the noise its rays show.

        It must hold the points (:meth:`_holds_points`), meet most normals within noise
        (QUADRIC_SHARE of them), and the rest must be clearly false (no more than
        QUADRIC_AMBIGUOUS missed by at most REJECT_DEG: far off, not a gradual falling away).
        A normal is met within noise when it is missed by at most QUADRIC_DEG or, failing
        that for the shape, when its highlight need move at most the allowance (PIXEL_MET,
        then, judged again (:meth:`run`), NOISE_SPREAD times the noise its rays show, from
        PIXEL_NOISE to PIXEL_WIDEST: :func:`_noise_allowance`; PIXEL_NOISE for a surface of
        revolution as it is fitted) for the shape to meet it (:meth:`_pixel_miss`). The
        rays met are those missed by at most QUADRIC_DEG, and, when the shape needed the pixel
        misses, those within PIXEL_MET.
        """
        judged = residual[inside]
        if not len(judged) or not self._holds_points(point_distance):
            return None
        met = inside & (residual <= QUADRIC_DEG)
        if _suffices(met[inside], judged):
            return met
        pixels = self._pixel_miss(shape, inside)
        self._noisier |= bool(np.any((pixels > PIXEL_MET) & (pixels <= PIXEL_NOISE)))
        allowance = self._allowance
        if allowance > PIXEL_MET and (not isinstance(shape, R.SurfaceOfRevolution)
                                      or by_noise):
            allowance = _noise_allowance(pixels[inside])
        if not _suffices((met | (pixels <= allowance))[inside], judged):
            return None
        return inside & (met | (pixels <= PIXEL_MET))

    def _pixel_miss(self, shape, rays: np.ndarray) -> np.ndarray:
        """How far (pixels) each ray's highlight must move for ``shape`` to meet its normal.

        ``|J+ m|``: ``m`` is the shape's unit normal less the asked one where the ray meets
        it, ``J`` its change per pixel (central differences over PIXEL_STEP). Infinite for a
        ray not among ``rays``, one that a moved ray misses, and one that no move within the
        linear model brings within QUADRIC_DEG. Noise on a highlight's pixel moves its ray
        along the surface, far where the ray grazes it: under a point lamp the true torus'
        normals were missed by up to 5-8 degrees at 1 px of noise, by at most 3.2 px.
        """
        step = PIXEL_STEP
        misses, ok = [], rays.copy()
        for shift in ((0.0, 0.0), (step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)):
            hits, met = self._anchors(shape, *self.scene.rays(shift=shift))
            ok &= met
            hits = np.where(met[:, None], hits, 0.0)
            g = _unit_rows(shape.gradient(hits))
            misses.append(g - self.scene.normals(hits, shift=shift))
        m = misses[0]
        jac = np.stack([misses[1] - misses[2], misses[3] - misses[4]], axis=2) / (2.0 * step)
        with np.errstate(all="ignore"):
            move = -np.einsum("mij,mj->mi", np.linalg.pinv(jac), m)
            left = np.linalg.norm(m + np.einsum("mij,mj->mi", jac, move), axis=1)
        ok &= np.isfinite(left) & (left <= 2.0 * math.sin(math.radians(QUADRIC_DEG) / 2.0))
        return np.where(ok, np.linalg.norm(move, axis=1), np.inf)

    def _anchors(self, shape, origins: np.ndarray, dirs: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Where rays meet ``shape``, and which meet it in the domain.

        A quadric's anchors are its crossings or nearest approaches, as its fit measures them.
        """
        lo, hi = self.grid.origin, self.grid.upper
        if isinstance(shape, Q.Quadric):
            anchors, _, enters = shape.intersect(origins, dirs, lo, hi)
            return anchors, enters
        return shape.intersect(origins, dirs, lo, hi, step=self.grid.spacing)

    def _holds_points(self, point_distance: np.ndarray) -> bool:
        """Whether a shape holds the points (``point_distance``: theirs, world units).

        Their median distance must be within QUADRIC_POINT_SIZE of the domain's size, and
        QUADRIC_POINT_SHARE of them within QUADRIC_POINT_REACH of it (with no points, it does).
        """
        if not len(point_distance):
            return True
        size = float(np.max(self.grid.upper - self.grid.origin))
        return bool(np.median(point_distance) <= QUADRIC_POINT_SIZE * size
                    and np.mean(point_distance <= QUADRIC_POINT_REACH * size)
                    >= QUADRIC_POINT_SHARE)

    def _torus(self, guess: Guess) -> T.Torus | None:
        """A ring torus that meets the normals as a quadric start must, or ``None``.

        Its rounds of fitting and intersecting (:meth:`_from_normal_lines`) end at a fit that
        is no ring; under a light other than the flash, when they find no start and the
        points are too few for their ellipsoid (:func:`points_ellipsoid`), they are made once
        more going on from such fits.
        """
        def fit(starts: np.ndarray, dirs: np.ndarray, ring: bool = True) -> T.Torus | None:
            if len(starts) < T.MIN_RAYS:
                return None
            return T.fit_torus(starts, dirs, self.scene.points.reshape(-1, 3),
                               scale=float(np.max(self.grid.upper - self.grid.origin)),
                               ring=ring)

        found = self._from_normal_lines(guess, fit,
                                        "a ring torus fitted to the highlights' normal lines")
        lo, hi = self.grid.origin, self.grid.upper
        if (found is None and not np.all(self._rays[2] == LIGHT_CAMERA)
                and points_ellipsoid(self.scene.points, lo, hi) is None):
            # a fit that is no ring ended the rounds. Under a light other than the flash its
            # hits give other lines, and the rounds may go on from it (a torus under a point
            # lamp with 3 points, seeds 0-4: the first fit from the quadric's hits a spindle;
            # refused, now 0.04-0.07 h). Only where the points are too few for their
            # ellipsoid and ring, the rounds' other firsts: going on from spindles everywhere
            # took a bottle under lamps from 0.78 to 2.96 s of start, and changed no start of
            # 168 catalogue scenes. By flash the lines are the rays, and a spindle fitted to
            # them stays one. Unless one is the start, these rounds' tori are no prior for the
            # grid fit: with a tenth false as well (seed 0), they swung between two tori 0.1
            # apart along the axis, the best met 38% of the normals, and the grid fit about
            # it was 0.77 h off and called supported (refused without it)
            prior = self._best
            found = self._from_normal_lines(
                guess, lambda starts, dirs: fit(starts, dirs, ring=False),
                "a ring torus fitted to the highlights' normal lines, from fits that are none")
            if found is None:
                self._best = prior
        return self._noisy_points_torus(found)

    def _asked(self, use: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """The normals the rays ``use`` ask, as a function of their hits ``(U, 3)``.

        Under a point lamp the normal a ray asks moves with its hit; a refit in pixels asks
        again at every evaluation.
        """
        def asked(at: np.ndarray) -> np.ndarray:
            placed = np.zeros((self.m, 3))
            placed[use] = at
            return self.scene.normals(placed)[use]

        return asked

    def _noisy_refit_basis(self, accepted, kind: type, min_rays: int) -> tuple | None:
        """Where a refit with the points weighed as noisy starts, or ``None``.

        The shape is ``accepted``, else the best shape of ``kind`` that held the points (the
        grid fit's prior). Returns it, the rays' hits on it, the rays that meet it in the
        domain, their residuals (degrees) and the rays it meets within REJECT_DEG, the ones
        refitted; ``None`` when there is no such shape or fewer than ``min_rays`` such rays.
        """
        shape = accepted
        if shape is None and self._best is not None and isinstance(self._best[1], kind):
            shape = self._best[1]
        if shape is None:
            return None
        origins, dirs, _, _ = self._rays
        hits, inside = shape.intersect(origins, dirs, self.grid.origin, self.grid.upper,
                                       step=self.grid.spacing)
        residual = self._residuals(shape, hits, inside)
        use = inside & (residual <= REJECT_DEG)
        if int(use.sum()) < min_rays:
            return None
        return shape, hits, inside, residual, use

    def _noisy_points_torus(self, accepted: T.Torus | None) -> T.Torus | None:
        """``accepted``, or a torus refitted with the points weighed as noisy.

        Points from structure from motion carry noise, and the fit to normal lines takes the
        tube's radius from them. The torus ``accepted`` (else the best one that held the
        points, the grid fit's prior) is refitted (:func:`warpspec.torus.refit_torus`) to the
        rays it meets within REJECT_DEG, the points weighed as noisy, when its points lie
        NOISY_TORUS_RATIO times further from it than those rays miss, in pixels
        (:meth:`_points_noisier`). The refit is taken when
        it is the start by itself and, when ``accepted`` was given, its rays miss by a median
        of at most NOISY_REFIT_GAIN times that one's (in pixels). Torus-lamps seed 5, points
        moved by a voxel per axis and half a pixel on the highlights: no torus was the start
        (its tube 0.058 too wide, 14% of the normals missed by 3-10 degrees); the refit's
        tube is 0.002 off, and it meets 98% of them.
        """
        if not self.scene.num_points or \
                (basis := self._noisy_refit_basis(accepted, T.Torus, T.MIN_RAYS)) is None:
            return accepted
        shape, _, _, _, use = basis
        origins, dirs, _, _ = self._rays
        rays = (origins[use], dirs[use], self._asked(use), self.scene.pixel_angles()[use])
        points = self.scene.points.reshape(-1, 3)
        misses = T.pixel_misses(shape, *rays)  # ``shape`` is ``accepted`` when one was given
        if not self._points_noisier(shape.value(points), float(np.median(rays[3])), misses,
                                    NOISY_TORUS_RATIO):
            return accepted
        self._say("a ring torus fitted again with the points as noisy")
        loose = T.refit_torus(shape, *rays, points, voxel=self.grid.spacing)
        if loose is None:
            return accepted
        if accepted is not None and not self._refit_closer(T.pixel_misses(loose, *rays), misses):
            return accepted
        prior = self._best
        if (refit := self._accept(loose)) is not None:
            return refit
        # a refit that is not the start is no prior either: on a pebble (no torus, points a
        # voxel off) it met 29% of the normals, not 21%, and the grid fit about it came out
        # 1.92 voxels off, not 0.77
        self._best = prior
        return accepted

    def _best_revolution_by_noise(self) -> R.SurfaceOfRevolution | None:
        """The surface of revolution that met most normals, if the noise its rays show allows.

        Judged the second time, a surface of revolution keeps PIXEL_NOISE while it is fitted:
        under lamps its refits stop at the first one taken, and a wider allowance takes a
        crude first fit (the bottle under lamps, seed 4 at 2 px: 84% of the normals within 3
        degrees, where its refit met 95%; 1.01 h). When none is taken, the one that met most
        normals and held the points (the grid fit's prior) is judged with NOISE_SPREAD times
        the noise its rays show; that seed's is the refit, 0.29 h (the grid fit 0.53).
        """
        best = self._best
        if self._allowance == PIXEL_MET or best is None or \
                not isinstance(best[1], R.SurfaceOfRevolution):
            return None
        accepted = self._accept(best[1], by_noise=True)
        self._best = best  # the prior stays as it was before this judging
        return accepted

    def _revolution(self, guess: Guess) -> R.SurfaceOfRevolution | None:
        """A surface of revolution that meets the normals as a quadric start must, or ``None``.

        By flash the rays are its normal lines (:func:`warpspec.revolution.fit_revolution`);
        under other lights the axis is first guessed from the normal lines through the rays'
        hits on the quadric, then found from the rays themselves
        (:func:`warpspec.revolution.fit_revolution_lit`), then refitted as :data:`LIT_REFITS`
        says.
        """
        lo, hi, voxel = self.grid.origin, self.grid.upper, self.grid.spacing
        origins, dirs, codes, _ = self._rays
        if np.all(codes == LIGHT_CAMERA):
            def fit(starts: np.ndarray, inward: np.ndarray) -> R.SurfaceOfRevolution | None:
                # about the refined axis and the closed-form one, the shape that meets more
                # of its lines within QUADRIC_DEG (the refined one first, kept on a tie).
                # The refined axis is the truth's on the catalogue's bottles, but a profile
                # about an axis a fraction of a degree off may meet more lines where few
                # highlights hold it: the sparse bottle (21 of seed 1's highlights, 3
                # points), about the refined axis, missed 2 of the neck's lines by 4.5 and
                # 6.4 degrees and was refused (the grid fit about it: 0.94 h from the truth);
                # about the closed-form axis (0.6 degrees off) it met 20 of 21 and was the
                # start, 0.38 h (measured before the profile's flatness, with which both
                # meet them)
                best = None
                for refine in (True, False):
                    shape = R.fit_revolution(starts, inward, self.scene.points, lo=lo,
                                             hi=hi, voxel=voxel, refine=refine)[0]
                    if shape is None:
                        continue
                    hits, inside = shape.intersect(starts, inward, lo, hi, step=voxel)
                    met = float(np.mean(miss_deg(shape.gradient(hits), -inward, inside)
                                        <= QUADRIC_DEG))
                    if best is None or met > best[0]:
                        best = (met, shape)
                return None if best is None else best[1]

            return self._from_normal_lines(
                guess, fit, "a surface of revolution fitted to the highlights' normal lines")
        if guess.kind != "sphere" or len(origins) < R.MIN_RAYS or not self.scene.num_points:
            return None
        if guess.lean >= RING_LENGTH:
            # cameras over the data more than around it: a patch, far likelier than a tube
            # (the fit takes seconds, and it would rarely be taken)
            return None
        self._say("a surface of revolution fitted to the highlights")
        # the first axis from the normal lines through the rays' hits on the quadric; false
        # highlights pull the quadric, and with it that axis, several degrees off, so the
        # hits on each shape not taken give the next one, while each meets more normals
        def fit(rays: np.ndarray, normals: np.ndarray, axis: tuple[np.ndarray, np.ndarray],
                tilted: bool = True, point_weight: float = R.POINT_WEIGHT):
            # the rays' normals asked at their hits on the shape before (a point light's
            # depend on them); the new shape and its own hits
            shape = R.fit_revolution_lit(origins[rays], dirs[rays], normals[rays],
                                         self.scene.points, lo=lo, hi=hi, voxel=voxel,
                                         axis=axis, tilted=tilted, point_weight=point_weight)
            if shape is None:
                return None, None, None
            return shape, *shape.intersect(origins, dirs, lo, hi, step=voxel)

        def attempt(first: tuple[np.ndarray, np.ndarray] | None):
            """The shape taken from this first axis (``None``: the quadric's hits' axis).

            With the rays' hits on it, which of them enter the domain and the rays it was
            fitted to; ``None`` when none is taken.
            """
            hits, inside, _ = self.quadric.intersect(origins, dirs, lo, hi)
            use = inside
            met = 0.0
            strict = False
            left = LIT_REFITS
            best = None
            while True:
                if int(use.sum()) < R.MIN_RAYS:
                    return from_axis(best)
                normals = self.scene.normals(hits)
                c, a = best_axis(hits[use], normals[use]) if first is None else first
                first = None
                if c is None:
                    return from_axis(best)
                shape, hits, inside = fit(use, normals, (c, a))
                if shape is None:
                    return from_axis(best)
                if (accepted := self._accept(shape, hits, inside)) is not None:
                    return accepted, hits, inside, use
                residual = self._residuals(shape, hits, inside)
                share = float(np.mean(residual[inside] <= QUADRIC_DEG))
                if best is None or share > best[0]:
                    best = (share, shape, hits, inside)
                if share <= met or left == 0:
                    if strict:
                        return from_axis(best)
                    # no better for leaving out the rays it missed by far, or no refit left:
                    # a false highlight it misses by a few degrees may hold it, so one last
                    # fit takes only the rays it meets within QUADRIC_DEG (bottle-lamps seed
                    # 11 at a quarter false: its third fit met 27 of 38 normals, better than
                    # each before, but a false one at 6.1 degrees and a true one at 5.5 held
                    # it from being the start; fitted to the 27 it is, exactly the 10 false
                    # ones rejected, where the grid fit made instead was 0.44 h off)
                    strict, left = True, 1
                    self._say("a surface of revolution fitted to the highlights it meets "
                              "within noise")
                left -= 1
                met = max(met, share)
                # the next fit takes only the rays this one meets within REJECT_DEG: a shape
                # near the truth misses the false highlights by far, and their normal lines
                # would pull the next axis off again
                use = inside & (residual <= (QUADRIC_DEG if strict else REJECT_DEG))

        def from_axis(best):
            """Every ray refitted from the axis of the shape that met most normals, or ``None``.

            The fits to the rays the shape before met within REJECT_DEG or QUADRIC_DEG find
            the axis, but leave out true highlights that the profile missed where false ones
            had bent it: the neck of bottle-lamps seed 21 at a quarter false, whose 7 true
            highlights the strict fit missed by 22-25 degrees, its axis 0.1 degree from the
            truth. From the right axis, every ray's hit is where its normal line meets it,
            and the profile's own robust weights leave the false ones out.
            """
            if best is None:
                return None
            _, shape, hits, inside = best
            if int(inside.sum()) < R.MIN_RAYS:
                return None
            self._say("a surface of revolution fitted to every highlight from the axis of "
                      "the one that met most")
            again, hits, inside = fit(inside, self.scene.normals(hits),
                                      (shape.base, shape.axis), tilted=False)
            if again is None or (accepted := self._accept(again, hits, inside)) is None:
                return None
            return accepted, hits, inside, inside

        found = attempt(None)
        if found is None and (ring := camera_ring(origins)) is not None:
            # false highlights can pull the quadric, and the axis through its hits, tens of
            # degrees off; cameras walked round an object stand on a ring about its axis
            self._say("a surface of revolution fitted from the cameras' ring")
            found = attempt(ring)
        if found is None:
            return self._noisy_points_revolution(None, fit)
        accepted, hits, inside, use = found
        kept = inside & (self.residual <= REJECT_DEG)
        if np.any(use & ~kept) and int(kept.sum()) >= R.MIN_RAYS:
            # fitted with rays it rejects: fitted again without them, from its own axis, which
            # is refined alone (the tilted starts found the same shape on bottle-lamps seeds
            # 0-5 at 10% and 25% false, in 24% more time)
            self._say("a surface of revolution fitted again without the rejected highlights")
            shape, hits, inside = fit(kept, self.scene.normals(hits),
                                      (accepted.base, accepted.axis), tilted=False)
            if shape is not None and (refit := self._accept(shape, hits, inside)) is not None:
                accepted = refit
            elif shape is not None:
                # true highlights the first shape missed by more than REJECT_DEG are missed
                # out of sample by the refit, a few degrees each, and a few such make it
                # ambiguous: the rays it meets within REJECT_DEG are tried back in once
                back = inside & (self._residuals(shape, hits, inside) <= REJECT_DEG)
                if np.any(back & ~kept):
                    self._say("a surface of revolution fitted again with the highlights "
                              "the refit meets")
                    shape, hits, inside = fit(back, self.scene.normals(hits),
                                              (shape.base, shape.axis), tilted=False)
                    if shape is not None and \
                            (refit := self._accept(shape, hits, inside)) is not None:
                        accepted = refit
        return self._noisy_points_revolution(self._without_ambiguous(accepted, fit), fit)

    def _noisy_points_revolution(self, accepted: R.SurfaceOfRevolution | None, fit: Callable
                                 ) -> R.SurfaceOfRevolution | None:
        """``accepted``, or a lit surface of revolution refitted with the points as noisy.

        Under lamps each ray's hit gives the profile's radius; points held exactly
        (:data:`~warpspec.revolution.POINT_WEIGHT`) that carry the noise of structure from
        motion bend the profile off the normals, or keep every fit from being the start. The
        shape ``accepted`` (else the best one that held the points, the grid fit's prior) is
        refitted from its own axis and the directions tilted from it (the axis was found
        while the points were held, and they tilt it), to the rays it meets within
        REJECT_DEG, with the points at :data:`~warpspec.revolution.NOISY_POINT_WEIGHT`:
        bottle-lamps seed 2, points half a voxel and a voxel off per axis, from its own axis
        alone 0.40 and 0.87 voxel from the truth after one iteration, 0.041 and 0.049 with the
        tilted starts (seeds 0, 1 and 3 unchanged). The refit is taken when it is the
        start by itself and, when ``accepted`` was given, misses the normals by a median of at
        most NOISY_POINT_GAIN times its median (with no floor, unlike the quadric's refit:
        NOISY_POINT_DEG says why). ``fit`` is :meth:`_revolution`'s, which is tried only
        with points.
        """
        if (basis := self._noisy_refit_basis(accepted, R.SurfaceOfRevolution,
                                             R.MIN_RAYS)) is None:
            return accepted
        shape, hits, inside, residual, use = basis
        before = _median_miss(residual, inside)
        self._say("a surface of revolution fitted again with the points as noisy")
        loose, hits, inside = fit(use, self.scene.normals(hits), (shape.base, shape.axis),
                                  point_weight=R.NOISY_POINT_WEIGHT)
        if loose is None or not inside.any():
            return accepted
        after = _median_miss(self._residuals(loose, hits, inside), inside)
        if accepted is not None and after > NOISY_POINT_GAIN * before:
            return accepted
        return self._accept(loose, hits, inside) or accepted

    def _without_ambiguous(self, accepted: R.SurfaceOfRevolution, fit: Callable
                           ) -> R.SurfaceOfRevolution:
        """A lit surface of revolution refitted without the rays it misses by a few degrees.

        A false highlight missed by less than REJECT_DEG stays in the fit and bends the
        profile where true highlights are few (the shoulder); fitted again from its own axis
        with only the rays met within QUADRIC_DEG, the shape is taken when it is a start by
        itself, leaves fewer rays between QUADRIC_DEG and REJECT_DEG and holds the met rays'
        own hits as closely as the shape before (:data:`HIT_SLACK_VOXELS`). ``fit`` is
        :meth:`_revolution`'s. Bottle-lamps seed 8, a quarter false: 0.17 voxel from the truth
        end to end before, 0.13 after (0.09 and 0.04 from the clean scene's mesh).
        """
        origins, dirs, _, _ = self._rays
        hits, inside = accepted.intersect(origins, dirs, self.grid.origin, self.grid.upper,
                                          step=self.grid.spacing)
        residual = self._residuals(accepted, hits, inside)
        ambiguous = int(np.sum(inside & _half_met(residual)))
        use = inside & (residual <= QUADRIC_DEG)
        if not ambiguous or int(use.sum()) < R.MIN_RAYS:
            return accepted
        self._say("a surface of revolution fitted again without the highlights it half meets")
        normals = self.scene.normals(hits)
        shape, hits, inside = fit(use, normals, (accepted.base, accepted.axis), tilted=False)
        if shape is None:
            return accepted
        if self._hits_off(shape, self.scene.normals(hits), use) > self._hits_off(
                accepted, normals, use) + HIT_SLACK_VOXELS:
            return accepted  # the refit lost the body the left-out rays held
        fewer = np.sum(inside & _half_met(self._residuals(shape, hits, inside))) < ambiguous
        if fewer and (refit := self._accept(shape, hits, inside)) is not None:
            return refit
        return accepted

    def _hits_off(self, shape: R.SurfaceOfRevolution, normals: np.ndarray,
                  rays: np.ndarray) -> float:
        """How far ``rays``' own hits lie from a lit ``shape``: the 90th percentile, voxels.

        A ray's own hit is where its normal line (the normal asked where it crosses the
        shape, ``normals`` of every ray) meets the shape's axis; 0 without any.
        """
        origins, dirs, _, _ = self._rays
        off, has_hit = R.lit_hit_distance(shape, origins[rays], dirs[rays], normals[rays])
        if not has_hit.any():
            return 0.0
        return float(np.percentile(off[has_hit], 90)) / self.grid.spacing

    def _torus_field(self, t: T.Torus, out: wp.array, grid: Grid | None = None, *,
                     unit: float = 1.0) -> None:
        """The ring torus' exact distance on ``grid`` (default: the requested one), per ``unit``."""
        grid = self.grid if grid is None else grid
        start = (np.asarray(grid.origin, dtype=np.float64) - t.centre) / unit
        wp.launch(K.torus_field, dim=grid.shape,
                  inputs=[wp.vec3(*(float(v) for v in start)), float(grid.spacing / unit),
                          wp.vec3(*(float(v) for v in t.axis)), float(t.R / unit),
                          float(t.r / unit)],
                  outputs=[out], device=self.device)

    def _revolution_field(self, rev: R.SurfaceOfRevolution, out: wp.array,
                          grid: Grid | None = None, *, unit: float = 1.0) -> None:
        """The surface of revolution's first-order distance on ``grid``, per ``unit``.

        ``grid`` defaults to the requested one.
        """
        grid = self.grid if grid is None else grid
        start = (np.asarray(grid.origin, dtype=np.float64) - rev.base) / unit

        def as_array(v: np.ndarray) -> wp.array:
            return wp.array(np.asarray(v, dtype=np.float32), dtype=float, device=self.device)

        wp.launch(K.revolution_field, dim=grid.shape,
                  inputs=[wp.vec3(*(float(v) for v in start)), float(grid.spacing / unit),
                          wp.vec3(*(float(v) for v in rev.axis)),
                          float(rev.heights[0] / unit),
                          float((rev.heights[1] - rev.heights[0]) / unit),
                          as_array(rev.radii / unit), as_array(rev.slopes())],
                  outputs=[out], device=self.device)

    def _prior_field(self, grid: Grid, out: wp.array, *, unit: float = 1.0) -> None:
        """The grid fit's prior on ``grid``, in units of ``unit``.

        The quadric, or the torus or surface of revolution that met more normals than it
        without being the start (:meth:`_accept`).
        """
        if isinstance(self.prior, T.Torus):
            self._torus_field(self.prior, out, grid, unit=unit)
        elif isinstance(self.prior, R.SurfaceOfRevolution):
            self._revolution_field(self.prior, out, grid, unit=unit)
        else:
            self._quadric_field(grid, out, unit=unit)

    def _from_normal_lines(self, guess: Guess, fit: Callable, message: str):
        """A shape fitted to the highlights' normal lines, if it is the start by itself.

        Tried only when the cameras stand all around. A flash-lit ray is a normal line
        itself; any other ray gives the normal line through its current hit (on the quadric
        first, then on the shape fitted last, the hits damped), up to :data:`TORUS_ROUNDS`
        times, and again from the points' ellipsoid (:func:`points_ellipsoid`), then from
        their ring torus (:func:`warpspec.torus.points_torus`), while none gives a start.
        After the first round only the rays the last shape meets closely give lines; by
        flash the rounds stop when those rays were fitted in a round before (the same lines
        give the same shape). ``fit`` takes the lines (a point outside the surface and the
        inward direction of each) and returns the shape (with ``intersect``, ``value`` and
        ``gradient``) or ``None``; a torus that is no ring
        (:attr:`warpspec.torus.Torus.is_ring`) only gives the next round's hits. The best
        round's shape is the start when it meets the normals and holds the points as a
        quadric must (:meth:`_start_met`); then the rays' residuals and weights are set
        (the rays it misses by more than REJECT_DEG are rejected).
        """
        if guess.kind != "sphere":
            return None
        self._say(message)
        origins, dirs, codes, _ = self._rays
        lo, hi = self.grid.origin, self.grid.upper
        outside = 2.0 * float(np.max(hi - lo))
        flash = codes == LIGHT_CAMERA
        firsts = [self.quadric]
        if not flash.all():
            # the quadric can pass a torus' hole and meet too few rays for a first fit: then
            # the rounds start again from the hits on the points' ellipsoid (a torus under a
            # point lamp met by its quadric on 18 and 31 of 48 and 51 rays, no ring fitted;
            # from a sphere about the points the normal lines all but met at its centre)
            if (spread := points_ellipsoid(self.scene.points, lo, hi)) is not None:
                firsts.append(spread)
            # and last from the ring torus through the points alone: with a quarter false
            # (torus-point seed 5) the normal lines through the hits on both quadrics gave
            # no ring (their first axes 57 and 11 degrees off), and the scene came out a sheet
            # 4.7 voxels off, open; the points' ring was 1.7 degrees off, and from it the
            # rounds found the torus
            if (ring := T.points_torus(self.scene.points)) is not None:
                firsts.append(ring)
        for first in firsts:
            hits, inside = (first.intersect(origins, dirs, lo, hi, step=self.grid.spacing)
                            if isinstance(first, T.Torus)
                            else first.intersect(origins, dirs, lo, hi)[:2])
            best = None
            trusted = np.ones(len(origins), dtype=bool)
            tried: set[bytes] = set()
            for _ in range(TORUS_ROUNDS):
                normals = self.scene.normals(hits)
                starts = np.where(flash[:, None], origins, hits + outside * normals)
                inward = np.where(flash[:, None], dirs, -normals)
                use = (flash | inside) & trusted
                if flash.all() and use.tobytes() in tried:
                    break  # by flash the lines stay; rays fitted before give a shape tried
                tried.add(use.tobytes())
                shape = fit(starts[use], inward[use])
                if shape is None:
                    break
                new_hits, new_inside = shape.intersect(origins, dirs, lo, hi,
                                                       step=self.grid.spacing)
                # the round that meets the most normals: under a point light the normals move
                # with the hits, and the rounds can swing about the shape, ever further
                residual = self._residuals(shape, new_hits, new_inside)
                # (ties: the smaller median miss)
                met = (_met(residual), -float(np.median(residual)))
                # the next round's lines: those of the rays this shape meets within REJECT_DEG
                # or among the closest TRUSTED_SHARE of them (a false highlight's line pulls
                # the shape off, round after round)
                limit = float(np.quantile(residual, TRUSTED_SHARE))
                trusted = residual <= max(REJECT_DEG, limit)
                candidate = not isinstance(shape, T.Torus) or shape.is_ring
                if candidate and (best is None or met > best[0]):
                    best = (met, shape, new_hits, new_inside)
                both = inside & new_inside
                moved = (float(np.max(np.linalg.norm(new_hits[both] - hits[both], axis=1)))
                         if both.any() else np.inf)
                hits = np.where(both[:, None], 0.5 * (hits + new_hits), new_hits)
                inside = new_inside
                if moved <= SETTLED_VOXELS * self.grid.spacing and both.sum() == inside.sum():
                    break
            if best is not None and (accepted := self._accept(*best[1:])) is not None:
                return accepted
        return None

    def _accept(self, shape, hits: np.ndarray | None = None, inside: np.ndarray | None = None,
                *, by_noise: bool = False):
        """``shape`` if it is the start by itself (:meth:`_start_met`), else ``None``.

        ``hits`` and ``inside``: the rays' crossings with it, when already traced; ``by_noise``:
        a surface of revolution too is judged by the noise its rays show. Sets the rays'
        residuals and weights (the rays it misses by more than REJECT_DEG are rejected).
        """
        origins, dirs, _, _ = self._rays
        points = self.scene.points.reshape(-1, 3)
        if hits is None:
            hits, inside = shape.intersect(origins, dirs, self.grid.origin, self.grid.upper,
                                           step=self.grid.spacing)
        if not inside.any():
            return None
        residual = self._residuals(shape, hits, inside)
        distance = np.abs(shape.value(points))
        share = _met(residual)
        if self._holds_points(distance) and (self._best is None or share > self._best[0]):
            self._best = (share, shape)  # the grid fit's prior, should none be the start
        if (met := self._start_met(shape, residual, inside, distance,
                                   by_noise=by_noise)) is None:
            return None
        self.residual = residual
        self.weights = (inside & (residual <= REJECT_DEG) | met).astype(float)
        return shape

    def _residuals(self, shape, hits: np.ndarray, inside: np.ndarray) -> np.ndarray:
        """The angle (degrees) between ``shape``'s normal and each ray's at its hit (180 off it)."""
        return miss_deg(shape.gradient(hits), self.scene.normals(hits), inside)

    def _quadric_field(self, grid: Grid, out: wp.array, *, unit: float = 1.0) -> None:
        """The quadric's first-order distance on ``grid``, in units of ``unit``."""
        q = self.quadric
        start = (np.asarray(grid.origin, dtype=np.float64) - q.centre) / q.scale
        wp.launch(K.quadric_field, dim=grid.shape,
                  inputs=[wp.vec3(*(float(v) for v in start)), float(grid.spacing / q.scale),
                          wp.array(q.coeffs.astype(np.float32), dtype=float,
                                   device=self.device), float(q.scale / unit)],
                  outputs=[out], device=self.device)

    def _use_level_rays(self, level: _Level) -> None:
        """The rays in the level's voxels (origins, and point lights' positions)."""
        self._rays_level = level
        origins, dirs, codes, vectors = self._rays
        vectors = np.where((codes == LIGHT_POINT)[:, None], level.to_grid(vectors), vectors)
        d, f32 = self.device, np.float32
        self._level_rays = (
            wp.array(level.to_grid(origins).astype(f32), dtype=wp.vec3, device=d),
            wp.array(dirs.astype(f32), dtype=wp.vec3, device=d),
            wp.array(codes.astype(np.int32), dtype=int, device=d),
            wp.array(vectors.astype(f32), dtype=wp.vec3, device=d))

    def _anchor(self, level: _Level) -> None:
        """Each ray's anchor on ``level``'s zero set, its kind and the normal asked there.

        The rays are taken in ``level``'s voxels: a fit of another level (a cross-validation
        fold on the coarsest grid) may have been made since ``level`` was.
        """
        if self.m == 0:
            return
        if self._rays_level is not level:
            self._use_level_rays(level)
        wp.launch(K.ray_anchor, dim=self.m,
                  inputs=[level.f, level.origin, level.h, *self._level_rays],
                  outputs=[self.anchor, self.kind, self.normals], device=self.device)

    def _update_weights(self, level: _Level) -> None:
        """Robust weights from the angle between each ray's normal and ``grad f`` there."""
        if self.m == 0:
            return
        wp.launch(K.sample_gradient, dim=self.m,
                  inputs=[level.f, level.origin, level.h, self.anchor], outputs=[self.grad],
                  device=self.device)
        g = self.grad.numpy().astype(np.float64)
        n = self.normals.numpy().astype(np.float64)
        kind = self.kind.numpy()
        cos = np.einsum("ij,ij->i", g, n) / np.maximum(np.linalg.norm(g, axis=1), 1e-12)
        angle = angle_deg(cos)
        live = kind != K.ANCHOR_NONE
        angle[~live] = 180.0
        self.residual = angle
        self.weights = Q.robust_weights(angle, live, limit_deg=LIMIT_DEG)
        self.weights[self.tried & live] = 1.0
        self.weights[self.excluded] = 0.0

    def _round(self, level: _Level, iterations: int) -> int:
        """Intersect, reweigh, build the samples, fit; returns the CG iterations."""
        fill_pockets(level.f, both=self._one_side)
        self._anchor(level)
        self._update_weights(level)
        grads, normals, values = self._samples(level)
        return level.solve(grads, normals, values, iterations)

    def _samples(self, level: _Level):
        """The samples of the fit, in the level's voxels (anchors are already)."""
        d = self.device
        anchors = self.anchor.numpy().astype(np.float64)
        kind = self.kind.numpy()
        normals = self.normals.numpy().astype(np.float64)
        dirs = self._rays[1]
        live = (kind != K.ANCHOR_NONE) & (self.weights > 0.0)
        xs, ws, ns = [], [], []
        for off, sw in zip(SAMPLE_OFFSETS, SAMPLE_WEIGHTS, strict=True):
            xs.append(anchors[live] + off * dirs[live])
            ws.append(sw * self.weights[live])
            ns.append(normals[live])
        xs = np.concatenate(xs) if xs else np.zeros((0, 3))
        ws = np.concatenate(ws) if ws else np.zeros(0)
        ns = np.concatenate(ns) if ns else np.zeros((0, 3))
        top = np.asarray(level.grid.shape, dtype=np.float64) - 1.0
        inside = np.all((xs >= 0.0) & (xs <= top), axis=1)
        xs, ws, ns = xs[inside], ws[inside], ns[inside]
        # values: the points (f = 0) and, weakly, the nearest approach of missing rays
        pts = level.to_grid(self.scene.points.reshape(-1, 3))
        miss = live & (kind == K.ANCHOR_NEAREST)
        ys = np.concatenate([pts, anchors[miss]])
        vw = np.concatenate([self.point_weights, MISS_WEIGHT * self.weights[miss]])
        ok = np.all((ys >= 0.0) & (ys <= top), axis=1)
        ys, vw = ys[ok], vw[ok]
        f32 = np.float32
        grads = (wp.array(xs.astype(f32), dtype=wp.vec3, device=d),
                 wp.array(ws.astype(f32), dtype=float, device=d))
        nrm = wp.array(ns.astype(f32), dtype=wp.vec3, device=d)
        values = (wp.array(ys.astype(f32), dtype=wp.vec3, device=d),
                  wp.array(vw.astype(f32), dtype=float, device=d))
        return grads, nrm, values


def fill_pockets(phi: wp.array, *, both: bool) -> int:
    """Remove the sealed pockets of a fitted field: regions of one sign that miss the boundary.

    A camera cannot see into a sealed cavity of a closed object, nor can a surface seen from
    one side hold a bubble: such a pocket is an overshoot of the fit between highlights (a
    ray that meets it first then holds it). Each face-connected region of ``phi > 0`` that
    touches no face of the grid has its sign flipped; with ``both`` (a surface seen from one
    side) the regions of ``phi <= 0`` too. On the host (scipy's labelling), before each fit of
    the ladder and on its result.

    Args:
        phi: The field on the grid, changed in place.
        both: Whether pockets of either sign are removed (else only those of ``phi > 0``).

    Returns:
        The number of pockets removed.
    """
    from scipy import ndimage

    values = phi.numpy()
    removed = 0
    for positive in ((True, False) if both else (True,)):
        mask = values > 0.0 if positive else values <= 0.0
        labels, count = ndimage.label(mask)
        if count <= 1:
            continue
        border = np.zeros(count + 1, dtype=bool)
        for axis in range(3):
            for end in (0, -1):
                border[np.unique(np.take(labels, end, axis=axis))] = True
        sealed = ~border
        sealed[0] = False
        if sealed.any():
            pocket = sealed[labels]
            values[pocket] = -values[pocket] if positive else np.maximum(-values[pocket], 1e-6)
            removed += int(sealed.sum())
    if removed:
        phi.assign(values)
    return removed


def rejected_summary(report: FitReport, scene) -> list[dict]:
    """One dict per rejected ray: index, camera, pixel, residual angle in degrees."""
    rows = []
    for i in report.rejected.tolist():
        rows.append({"index": int(i), "camera": int(scene.spec_camera[i]),
                     "pixel": [float(v) for v in scene.spec_pixel[i]],
                     "residual_deg": float(report.residual_deg[i])
                     if math.isfinite(report.residual_deg[i]) else None})
    return rows
