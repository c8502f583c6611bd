"""The narrow band: a compacted list of the nodes near the zero set, bit-packed.

Each entry codes a node ``(i, j, k)`` (10 bits an axis where the grid allows, else its flat
index); :func:`band_slot` decodes entry ``s`` (or the ``s``-th from the end) and returns
``(-1, ...)`` past the count, so that kernels launched at full capacity skip those threads.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

__all__ = [
    "band_slot",
    "build_band",
    "launch_build_band",
    "unflatten",
]

@wp.func
def unflatten(t: int, shape: wp.vec3i) -> wp.vec3i:
    """Node ``(i, j, k)`` of the linear index ``t`` of a C-ordered 3-D array."""
    plane = shape[1] * shape[2]
    return wp.vec3i(t // plane, (t // shape[2]) % shape[1], t % shape[2])

@wp.func
def packable(shape: wp.vec3i) -> bool:
    """Whether a node of ``shape`` fits in one int as ``i << 20 | j << 10 | k``."""
    return shape[0] <= 2048 and shape[1] <= 1024 and shape[2] <= 1024

@wp.func
def band_node(code: int, shape: wp.vec3i) -> wp.vec3i:
    """Node ``(i, j, k)`` of a narrow band's entry (see :func:`build_band`).

    Grids up to 2048 x 1024 x 1024 nodes store the node bit-packed, which decodes in a few
    shifts; larger ones store the linear index, which costs three integer divisions (about
    16 ns more a node on the CPU, on every pass over the band).
    """
    if packable(shape):
        return wp.vec3i(code >> 20, (code >> 10) & 1023, code & 1023)
    return unflatten(code, shape)

@wp.func
def band_slot(band: wp.array[int], count: wp.array[int], s: int, reverse: int,
              shape: wp.vec3i) -> wp.vec3i:
    """Node of slot ``s`` of a band list (from its end when ``reverse``), or -1s past the list."""
    n = count[0]
    if s >= n:
        return wp.vec3i(-1, -1, -1)
    return band_node(band[wp.where(reverse == 1, n - 1 - s, s)], shape)

@wp.kernel
def build_band(
    phi: wp.array[float],
    shape: wp.vec3i,
    width: float,
    band: wp.array[int],
    count: wp.array[int],
):
    """Append every node with ``|phi| <= width`` to ``band`` (``phi`` flattened, C order).

    An entry is the node bit-packed as ``i << 20 | j << 10 | k`` where the grid allows it
    (:func:`packable`), else its linear index; :func:`band_node` decodes either. Both orders
    agree with C order. The order of the list is not significant (on the CPU it comes out in
    index order).
    """
    t = wp.tid()
    if wp.abs(phi[t]) <= width:
        code = t
        if packable(shape):
            n = unflatten(t, shape)
            code = (n[0] << 20) | (n[1] << 10) | n[2]
        slot = wp.atomic_add(count, 0, 1)
        band[slot] = code

def launch_build_band(phi: wp.array, band: wp.array, count: wp.array, *, width: float) -> None:
    """Collect the nodes with ``|phi| <= width`` into ``band``; their number into ``count``."""
    count.zero_()
    # A 1-D launch over the flattened array: on the CPU a 3-D launch costs ~18 ns a thread.
    flat = phi.flatten()
    wp.launch(build_band, dim=flat.shape[0], inputs=[flat, wp.vec3i(*phi.shape), float(width)],
              outputs=[band, count], device=phi.device)
