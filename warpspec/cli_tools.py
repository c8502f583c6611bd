"""Subcommands for synthetic scenes and evaluation (``warpspec synth``, ``warpspec evaluate``)."""

from __future__ import annotations

import argparse

__all__ = ["add_parsers"]


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register this module's subcommands on the ``warpspec`` parser."""
