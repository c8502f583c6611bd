"""Choices shared by the Python API and the command line (no heavy imports here)."""

__all__ = ["ITERATIONS", "STARTS", "default_iterations"]

STARTS = ("implicit", "height", "paper")
"""Starting surfaces of :class:`warpspec.Reconstructor`; the first is the default (see
docs/DESIGN.md section 7)."""

ITERATIONS = 300
"""Iterations of the flow on a grid of :data:`ITERATIONS_AT` cells or fewer."""
ITERATIONS_AT = 64
MIN_ITERATIONS = 50
"""Fewest iterations the automatic schedule gives a fine grid."""


def default_iterations(resolution: int) -> int:
    """Iterations of the flow for a grid of ``resolution`` cells along its longest side.

    The start is solved coarse to fine up to the requested grid (docs/DESIGN.md section 7), so
    the flow only refines it, locally: the same number of iterations covers a quarter of the
    time on a grid twice as fine (``dt ~ h^2``), and half the distance in voxels of the coarser
    grid; the schedule keeps the distance in world units, ``ITERATIONS * ITERATIONS_AT /
    resolution``, never below ``MIN_ITERATIONS``.
    """
    if resolution <= ITERATIONS_AT:
        return ITERATIONS
    return max(MIN_ITERATIONS, round(ITERATIONS * ITERATIONS_AT / resolution))
