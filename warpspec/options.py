"""Choices shared by the Python API and the command line (no heavy imports here)."""

__all__ = ["STARTS"]

STARTS = ("implicit", "height", "paper")
"""Starting surfaces of :class:`warpspec.Reconstructor`; the first is the default (see
docs/DESIGN.md section 7)."""
