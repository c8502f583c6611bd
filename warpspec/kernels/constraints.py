"""Constraint fields: the Gaussian point attraction and the ownership of the normals.

- ``G(x) = max_y exp(-|x - y|^2 / (2 eps^2))`` is splatted point by point over the nodes within
  ``cutoff * eps`` of each point (``exp(-cutoff^2 / 2)`` is dropped beyond), so its cost grows
  with the number of points times a small window, never points times voxels. The paper sums
  the Gaussians; where they do not overlap (a few points, as in its experiments) the maximum is
  the same, and for a dense cloud from structure from motion the sum grows with the density
  (a thousand points within a voxel decay ``phi`` a thousand times faster, flattening it to
  zero over several voxels), where the maximum pulls as one point does.
- The extended normal field ``V`` is held as an ``owner`` index per node: two passes over the
  nodes within ``r_N`` of each ray's intersection pick the nearest intersection with atomic
  minima, first on the distance, then on the ray index among equal distances, so the result
  does not depend on thread order. The second pass also marks the unowned six-neighbours of
  each owned node :data:`NEIGHBOUR_OWNED` (an atomic minimum too: any ray index wins over the
  mark), so that every other node, :data:`NO_OWNER`, provably has no normal term.
"""

from __future__ import annotations

import math

import warp as wp

from .flow import NEIGHBOUR_OWNED, NO_OWNER

wp.set_module_options({"enable_backward": False})

__all__ = [
    "GAUSSIAN_CUTOFF",
    "NEIGHBOUR_OWNED",
    "NO_OWNER",
    "launch_claim_normals",
    "launch_gaussian",
    "window_span",
]

GAUSSIAN_CUTOFF = 5.0


@wp.func
def node_position(origin: wp.vec3, h: float, i: int, j: int, k: int) -> wp.vec3:
    """World position of node ``(i, j, k)``."""
    return origin + h * wp.vec3(float(i), float(j), float(k))


@wp.func
def window_node(
    centre: wp.vec3, origin: wp.vec3, h: float, radius: float, span: int, offset: int
) -> wp.vec3i:
    """Node number ``offset`` of the cube of ``span^3`` nodes covering a ball around ``centre``."""
    q = (centre - origin) / h
    lo_i = int(wp.floor(q[0] - radius))
    lo_j = int(wp.floor(q[1] - radius))
    lo_k = int(wp.floor(q[2] - radius))
    a = offset // (span * span)
    b = (offset // span) % span
    c = offset % span
    return wp.vec3i(lo_i + a, lo_j + b, lo_k + c)


@wp.func
def inside(shape: wp.vec3i, n: wp.vec3i) -> bool:
    """Whether a node index lies on the grid."""
    return (
        n[0] >= 0 and n[1] >= 0 and n[2] >= 0
        and n[0] < shape[0] and n[1] < shape[1] and n[2] < shape[2]
    )


@wp.kernel
def gaussian_splat(
    points: wp.array[wp.vec3],
    origin: wp.vec3,
    h: float,
    eps: float,
    cutoff: float,
    span: int,
    gauss: wp.array3d[float],
):
    """Raise the nodes within ``cutoff * eps`` of each point to its Gaussian (atomic max)."""
    p, offset = wp.tid()
    y = points[p]
    n = window_node(y, origin, h, cutoff * eps / h, span, offset)
    shape = wp.vec3i(gauss.shape[0], gauss.shape[1], gauss.shape[2])
    if not inside(shape, n):
        return
    d = node_position(origin, h, n[0], n[1], n[2]) - y
    r2 = wp.dot(d, d)
    if r2 <= (cutoff * eps) * (cutoff * eps):
        wp.atomic_max(gauss, n[0], n[1], n[2], wp.exp(-r2 / (2.0 * eps * eps)))


@wp.func
def ball_node(
    x: wp.vec3, origin: wp.vec3, h: float, radius: float, span: int, offset: int,
    shape: wp.vec3i,
) -> wp.vec4:
    """Node number ``offset`` of the window around ``x`` and its distance to ``x``.

    Returns ``(i, j, k, d)``; ``d`` is negative when the node is off the grid or farther than
    ``radius``.
    """
    n = window_node(x, origin, h, radius / h, span, offset)
    if not inside(shape, n):
        return wp.vec4(0.0, 0.0, 0.0, -1.0)
    d = wp.length(node_position(origin, h, n[0], n[1], n[2]) - x)
    if d > radius:
        d = -1.0
    return wp.vec4(float(n[0]), float(n[1]), float(n[2]), d)


@wp.kernel
def claim_distance(
    hits: wp.array[wp.vec3],
    active: wp.array[int],
    origin: wp.vec3,
    h: float,
    radius: float,
    span: int,
    dist: wp.array3d[float],
):
    """First pass of the nearest-intersection rule: the smallest distance per node."""
    r, offset = wp.tid()
    if active[r] == 0:
        return
    shape = wp.vec3i(dist.shape[0], dist.shape[1], dist.shape[2])
    b = ball_node(hits[r], origin, h, radius, span, offset, shape)
    if b[3] >= 0.0:
        wp.atomic_min(dist, int(b[0]), int(b[1]), int(b[2]), b[3])


@wp.kernel
def claim_owner(
    hits: wp.array[wp.vec3],
    active: wp.array[int],
    origin: wp.vec3,
    h: float,
    radius: float,
    span: int,
    dist: wp.array3d[float],
    owner: wp.array3d[int],
):
    """Second pass: among the rays at the smallest distance, the lowest index owns the node."""
    r, offset = wp.tid()
    if active[r] == 0:
        return
    shape = wp.vec3i(dist.shape[0], dist.shape[1], dist.shape[2])
    b = ball_node(hits[r], origin, h, radius, span, offset, shape)
    if b[3] < 0.0:
        return
    i = int(b[0])
    j = int(b[1])
    k = int(b[2])
    if b[3] == dist[i, j, k]:
        wp.atomic_min(owner, i, j, k, r)
        for axis in range(3):
            for side in range(2):
                n = wp.vec3i(i, j, k)
                n[axis] = n[axis] + 2 * side - 1
                if inside(shape, n):
                    wp.atomic_min(owner, n[0], n[1], n[2], NEIGHBOUR_OWNED)


def window_span(radius_in_cells: float) -> int:
    """Nodes per axis of the cube that covers a ball of the given radius (in cells)."""
    return 2 * int(math.ceil(radius_in_cells)) + 2


def launch_gaussian(
    points: wp.array,
    gauss: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    eps: float,
    cutoff: float = GAUSSIAN_CUTOFF,
) -> None:
    """Fill ``gauss`` with ``G(x) = max_y exp(-|x - y|^2 / (2 eps^2))`` (zeroes it first).

    Args:
        points: Point constraints (vec3).
        gauss: Destination field (float32, 3-D).
        origin: World position of node ``(0, 0, 0)``.
        spacing: Grid spacing ``h``.
        eps: Standard deviation of each Gaussian, world units.
        cutoff: Contributions beyond ``cutoff * eps`` are dropped.
    """
    gauss.zero_()
    if points.shape[0] == 0:
        return
    span = window_span(cutoff * eps / spacing)
    wp.launch(
        gaussian_splat,
        dim=(points.shape[0], span**3),
        inputs=[points, wp.vec3(*origin), float(spacing), float(eps), float(cutoff), span],
        outputs=[gauss],
        device=gauss.device,
    )


def launch_claim_normals(
    hits: wp.array,
    active: wp.array,
    dist: wp.array,
    owner: wp.array,
    *,
    origin: tuple[float, float, float],
    spacing: float,
    radius: float,
) -> None:
    """Rebuild ``owner``: each node within ``radius`` of an active hit takes the nearest ray.

    ``dist`` is scratch. Unowned nodes next to an owned one get :data:`NEIGHBOUR_OWNED`, the
    others :data:`NO_OWNER`.
    """
    dist.fill_(1.0e30)
    owner.fill_(NO_OWNER)
    if hits.shape[0] == 0:
        return
    span = window_span(radius / spacing)
    args = [hits, active, wp.vec3(*origin), float(spacing), float(radius), span, dist]
    dim = (hits.shape[0], span**3)
    wp.launch(claim_distance, dim=dim, inputs=args, device=dist.device)
    wp.launch(claim_owner, dim=dim, inputs=args, outputs=[owner], device=dist.device)


