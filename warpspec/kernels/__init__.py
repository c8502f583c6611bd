"""Warp kernels and their launchers, one module per concern.

Every module sets ``enable_backward=False``: warpspec never differentiates its kernels.
"""
