"""The narrow-band tracker: the band around the zero set, reinitialisation and rollback.

Between two reinitialisations the flow updates only the nodes of the band (a compacted list
of the nodes within ``width`` voxels of the zero set). Each reinitialisation checks the level
set, redistances it (the band alone, or the whole grid every :data:`FULL_REINIT_EVERY`-th
time), rebuilds the band and keeps the result as the last good state, to which a non-finite
step rolls back.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..kernels.band import launch_build_band
from ..kernels.measures import MEASURE_SLOTS, launch_measures
from .workspace import Workspace

__all__ = ["FULL_REINIT_EVERY", "BandTracker"]

FULL_REINIT_EVERY = 10
"""Every this many reinitialisations redistance the whole grid (up to the cap), not the band
alone: nodes beyond the band keep old distances between, whose error grows as the surface
moves (the flow moves it a fraction of a voxel in 100 iterations)."""
FAR_CAP_MARGIN = 4.0
"""Voxels beyond the narrow band that a full redistance still computes exactly."""


class BandTracker:
    """Keep a workspace's narrow band, redistance its level set and roll back a bad step.

    Args:
        ws: The workspace (its ``band`` is ``None`` when every node is updated).
        width: Half-width of the band, in voxel widths (``None``: no band).
    """

    def __init__(self, ws: Workspace, *, width: float | None) -> None:
        self.ws = ws
        self.width = width
        self.size = 0
        self.count = 0  # reinitialisations so far
        self.good_iteration = 0

    def __repr__(self) -> str:
        band = "every node" if self.ws.band is None else f"{self.size} band nodes"
        return f"BandTracker({band}, {self.count} reinitialisations)"

    @property
    def far_cap(self) -> float | None:
        """Voxels beyond which a full redistance may clamp (only the band is ever read).

        With a narrow band the flow, the measures and the band's rebuild read ``phi`` only
        within ``width`` voxels of the zero set, and the rays only its sign; capping the
        sweeps a little beyond makes a full redistance about three times cheaper. Without a
        band the whole grid is updated, and nothing is capped.
        """
        return None if self.ws.band is None else self.width + FAR_CAP_MARGIN

    def rebuild(self) -> None:
        """Collect the narrow band around the current zero set.

        Both buffers of the ping-pong pair get the current ``phi``: the band step writes only
        the band, so every other node must agree in both.
        """
        ws = self.ws
        if ws.band is None:
            return
        wp.copy(ws.tmp, ws.phi)
        launch_build_band(ws.phi, ws.band, ws.band_count, width=self.width * ws.grid.spacing)
        # On the CPU the launch is synchronous and the count costs nothing to read; on CUDA
        # the band kernels run at full capacity and skip the threads past the count.
        if ws.device.is_cpu:
            self.size = int(ws.band_count.numpy()[0])
        else:
            self.size = ws.band.shape[0]

    def keep_good(self, iteration: int) -> None:
        """Remember the current ``phi`` as the last good state, reached at ``iteration``."""
        wp.copy(self.ws.good, self.ws.phi)
        self.good_iteration = iteration

    def reinitialize(self, iteration: int) -> None:
        """Redistance ``phi`` (checked finite first), rebuild the band, keep it as good."""
        ws = self.ws
        self.count += 1
        if ws.band is None or self.count % FULL_REINIT_EVERY == 0:
            ws.redistancer.reinitialize(ws.phi, cap=self.far_cap)
        else:
            ws.redistancer.reinitialize_band(ws.phi, ws.band, ws.band_count, size=self.size,
                                             width=self.width + 2.0)
        ws.version += 1
        self.rebuild()
        self.keep_good(iteration)

    def sums(self) -> np.ndarray:
        """Reduce the measures over the band (or the grid) into the slots of ``MEASURE_SLOTS``."""
        ws = self.ws
        launch_measures(ws.phi, ws.owner, ws.normals, ws.hits, ws.active, ws.points, ws.sums,
                        origin=ws.origin, spacing=ws.grid.spacing, band=ws.band,
                        count=ws.band_count, size=self.size)
        return ws.sums.numpy()

    def nonfinite(self, sums: np.ndarray) -> int:
        """Nodes of non-finite value among those ``sums`` reduced."""
        return int(sums[MEASURE_SLOTS["nonfinite"]])

    def roll_back(self) -> int:
        """Restore the last good state and rebuild its band; returns its iteration."""
        ws = self.ws
        wp.copy(ws.phi, ws.good)
        wp.copy(ws.tmp, ws.good)
        ws.version += 1
        self.rebuild()
        return self.good_iteration
