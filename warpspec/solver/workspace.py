"""The device arrays of one reconstruction on one grid, and the passes that fill them.

A :class:`Workspace` owns the level set and its ping-pong twin, the last good level set, the
point Gaussians, the ownership of the constraint normals, the rays and their intersections,
the narrow band's list and the redistancer's scratch, all on one device. It knows nothing of
the flow's schedule: the tracker and the :class:`~warpspec.solver.Reconstructor` drive it.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..errors import InputError
from ..grid import Grid
from ..kernels.constraints import launch_claim_normals, launch_gaussian
from ..kernels.measures import NUM_SLOTS
from ..kernels.rays import launch_intersect
from ..kernels.redistance import Redistancer
from ..scene import Scene
from .state import free_host_memory

__all__ = ["BYTES_PER_VOXEL", "REINIT_BAND", "Workspace"]

# Device bytes per voxel: phi, its ping-pong twin, the last good phi, G, owner and the narrow
# band's list (4 each), and the redistancer's scratch (5, shared with the ownership pass).
BYTES_PER_VOXEL = 29

REINIT_BAND = "gradient"
"""How the redistancer freezes the nodes next to the zero set (docs/DESIGN.md, "Method notes")."""


class Workspace:
    """The device arrays of one grid, with the rays, points and constraint fields of a scene.

    Attributes:
        phi: The level set (live: the next step writes its twin and the two swap).
        tmp: Its ping-pong twin, and scratch during the start.
        good: The last good level set (restored after a non-finite step); scratch at start.
        version: Bumped whenever ``phi`` changes; the hits know which ``phi`` they meet.

    Args:
        scene: The scene.
        grid: The grid.
        device: The Warp device.
        gaussian_width: Standard deviation of the point Gaussians, in voxel widths.
        normal_radius: Radius of the balls that carry the constraint normals, in voxel widths.
        band: Allocate the narrow band's list.

    Raises:
        InputError: If the arrays would not fit in the device's free memory.
    """

    def __init__(self, scene: Scene, grid: Grid, device: wp.Device, *, gaussian_width: float,
                 normal_radius: float, band: bool) -> None:
        check_memory(grid, device)
        self.grid = grid
        self.device = d = device
        self.normal_radius = normal_radius
        shape = grid.shape
        h = grid.spacing
        origins, dirs = scene.rays()
        codes, vectors = scene.ray_lights()
        m = len(origins)
        self.origin = tuple(float(v) for v in grid.origin)
        self.phi = wp.zeros(shape, dtype=float, device=d)
        self.tmp = wp.zeros(shape, dtype=float, device=d)
        self.gauss = wp.zeros(shape, dtype=float, device=d)
        self.owner = wp.zeros(shape, dtype=int, device=d)
        self.ray_origin = wp.array(origins.astype(np.float32), dtype=wp.vec3, device=d)
        self.ray_dir = wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=d)
        self.light_code = wp.array(codes.astype(np.int32), dtype=int, device=d)
        self.light_vec = wp.array(vectors.astype(np.float32), dtype=wp.vec3, device=d)
        self.hits = wp.zeros(m, dtype=wp.vec3, device=d)
        self.active = wp.zeros(m, dtype=int, device=d)
        self.normals = wp.zeros(m, dtype=wp.vec3, device=d)
        self.ray_index = np.arange(m)  # scene index of each ray the flow uses
        self.points = wp.array(scene.points.astype(np.float32).reshape(-1, 3), dtype=wp.vec3,
                               device=d)
        self.sums = wp.zeros(NUM_SLOTS, dtype=wp.float64, device=d)
        self.redistancer = Redistancer(shape, h, d, band=REINIT_BAND)
        self.good = wp.zeros(shape, dtype=float, device=d)
        # The ownership pass and the redistancer never run at once: they share a scratch field.
        self.owner_dist = self.redistancer.distance
        self.band = wp.zeros(grid.size, dtype=int, device=d) if band else None
        self.band_count = wp.zeros(1, dtype=int, device=d)
        self.progress = None
        """Called with a few words as each stage of a start begins (or ``None``)."""
        self.far_cap: float | None = None
        """Voxels beyond which a full redistance may clamp (set from the band's tracker)."""
        self.version = 0
        self.hits_version = -1
        launch_gaussian(self.points, self.gauss, origin=self.origin, spacing=h,
                        eps=gaussian_width * h)

    def __repr__(self) -> str:
        return (f"Workspace({'x'.join(map(str, self.grid.shape))} on {self.device.alias}, "
                f"{self.hits.shape[0]} rays, {self.points.shape[0]} points)")

    def swap(self) -> None:
        """Make the ping-pong twin the level set (after a pass wrote it)."""
        self.phi, self.tmp = self.tmp, self.phi
        self.version += 1

    def intersect(self) -> None:
        """Intersect the rays with ``phi`` and give each node near a hit its nearest ray."""
        launch_intersect(self.phi, self.ray_origin, self.ray_dir, self.light_code,
                         self.light_vec, self.hits, self.active, self.normals,
                         origin=self.origin, spacing=self.grid.spacing)
        launch_claim_normals(self.hits, self.active, self.owner_dist, self.owner,
                             origin=self.origin, spacing=self.grid.spacing,
                             radius=self.normal_radius * self.grid.spacing)
        self.hits_version = self.version

    def current_hits(self) -> None:
        """Intersect the rays unless they already meet this ``phi``."""
        if self.hits_version != self.version:
            self.intersect()

    def use_rays(self, keep: np.ndarray) -> None:
        """Restrict the flow to the rays ``keep`` (indices into the scene's specularities)."""
        d = self.device
        self.ray_index = keep
        for name in ("ray_origin", "ray_dir", "light_code", "light_vec"):
            arr = getattr(self, name)
            setattr(self, name, wp.array(arr.numpy()[keep], dtype=arr.dtype, device=d))
        m = len(keep)
        self.hits = wp.zeros(m, dtype=wp.vec3, device=d)
        self.active = wp.zeros(m, dtype=int, device=d)
        self.normals = wp.zeros(m, dtype=wp.vec3, device=d)

    def scene_hits(self, num_specularities: int) -> np.ndarray:
        """The hits of the current ``phi`` per scene ray, ``(M, 3)``.

        NaN where a ray misses or takes no part in the flow.
        """
        self.current_hits()
        used = self.hits.numpy().astype(np.float64)
        used[self.active.numpy() == 0] = np.nan
        hits = np.full((num_specularities, 3), np.nan)
        hits[self.ray_index] = used
        return hits


def check_memory(grid: Grid, device: wp.Device) -> None:
    """Refuse a grid whose arrays would not fit in the free memory of ``device``.

    Raises:
        InputError: Naming the resolution, the need and what is free.
    """
    need = grid.size * BYTES_PER_VOXEL
    have = int(device.free_memory) if device.is_cuda else free_host_memory()
    if have is not None and need > have:
        raise InputError(
            f"resolution: a {'x'.join(map(str, grid.shape))} grid needs about "
            f"{need / 2**30:.1f} GiB on {device.alias} but only {have / 2**30:.1f} GiB "
            "is free; lower the resolution"
        )
