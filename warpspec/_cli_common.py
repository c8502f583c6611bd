"""Pieces shared by the command line's subcommands: argument types, paths, atomic writes."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Sequence
from pathlib import Path

from ._atomic import atomic_write
from .errors import InputError
from .options import OPTIONS

__all__ = [
    "add_option",
    "atomic_write",
    "finite",
    "input_file",
    "integer",
    "json_safe",
    "non_negative",
    "non_negative_int",
    "output_path",
    "positive",
    "positive_int",
]


def output_path(path: str, allowed: Sequence[str], flag: str) -> Path:
    """An output path with a known extension in a folder that exists and can be written."""
    p = Path(path)
    if p.suffix.lower() not in allowed:
        raise InputError(
            f"{flag}: {path!r} has an unsupported extension; use one of {', '.join(allowed)}"
        )
    parent = p.parent
    if not parent.is_dir():
        raise InputError(f"{flag}: the folder {str(parent)!r} does not exist")
    if p.is_dir():
        raise InputError(f"{flag}: {path!r} is a folder, expected a file name")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag}: the folder {str(parent)!r} is not writable")
    return p


def input_file(path: str, flag: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"{flag}: no such file {path!r}")
    if p.is_dir():
        hint = ""
        if (p / "cameras.txt").exists() or (p / "cameras.bin").exists():
            hint = "; for a COLMAP model, make a scene file with 'warpspec import-colmap' first"
        raise InputError(f"{flag}: {path!r} is a folder, expected a file{hint}")
    return p


def json_safe(value):
    """``value`` with every non-finite float in it (NaN, inf) made ``None``: standard JSON."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _int_at_least(text: str, low: int | None, what: str) -> int:
    """An integer not below ``low`` (no bound when ``None``); ``what`` names it in errors."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if low is not None and value < low:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


def positive_int(text: str) -> int:
    return _int_at_least(text, 1, "a positive integer")


def non_negative_int(text: str) -> int:
    return _int_at_least(text, 0, "a non-negative integer")


def finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def non_negative(text: str) -> float:
    value = finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def positive(text: str) -> float:
    value = finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def integer(text: str) -> int:
    return _int_at_least(text, None, "an integer")


def add_option(parser: argparse.ArgumentParser, name: str, *, help: str | None = None,
               shown: str | None = None, **overrides) -> None:
    """Add the flag of the option ``name`` of :data:`warpspec.options.OPTIONS`.

    Its type, check, choices, default and help come from the option; ``help`` replaces the
    help (the option's default is still appended) and ``overrides`` go to ``add_argument``
    (``default=None``, say, to tell an omitted flag from its default); ``shown`` replaces
    the default written in the help.
    """
    option = OPTIONS[name]

    def parse(text: str):
        try:
            return option.parse(text)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc).partition(": ")[2]) from None

    parse.__name__ = name
    if shown is None:
        shown = ("none" if option.default is None else option.default
                 if option.kind == "choice" else f"{option.default:g}")
    kwargs = {"default": option.default}
    if option.kind == "choice":
        kwargs["choices"] = option.choices
    else:
        kwargs["type"] = parse
    kwargs.update(overrides)
    text = option.help if help is None else help
    parser.add_argument(option.flag, help=f"{text} (default {shown})".replace("%", "%%"),
                        **kwargs)
