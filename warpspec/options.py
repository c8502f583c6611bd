"""Every option of a reconstruction: its default, unit, range and check, defined once.

The Python API (:class:`warpspec.Reconstructor`, :func:`warpspec.reconstruct`) takes its
defaults and checks from :data:`OPTIONS`, and the command line builds its flags, defaults and
help from the same table, so a default is written here and nowhere else. No heavy imports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError

__all__ = [
    "DEFAULTS",
    "MAX_ALPHA",
    "MAX_BULGE",
    "OPTIONS",
    "STARTS",
    "Option",
    "check_non_negative_int",
    "check_positive_int",
    "check_real",
    "default_iterations",
]

STARTS = ("implicit", "height", "paper")
"""Starting surfaces of :class:`warpspec.Reconstructor`; the first is the default (see
docs/DESIGN.md section 7)."""

MAX_ALPHA = 1e4
"""Largest smoothness weight: the time step shrinks as ``1 / (1 + alpha)``, so beyond this the
flow does not move in any number of iterations, and ``alpha / h`` nears float32's range."""
MAX_BULGE = 100.0
"""Largest ``|bulge|``: the start moves by ``bulge`` times the distance to the nearest point,
so beyond this it leaves any domain (the paper uses 0.3 and 0.5)."""


def check_positive_int(name: str, value: object) -> int:
    """``value`` as an ``int`` if it is an integer of at least 1.

    Raises:
        InputError: Otherwise, naming ``name``.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"{name}: must be a positive integer, got {value!r}")
    return int(value)


def check_non_negative_int(name: str, value: object) -> int:
    """``value`` as an ``int`` if it is an integer of at least 0.

    Raises:
        InputError: Otherwise, naming ``name``.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise InputError(f"{name}: must be a non-negative integer, got {value!r}")
    return int(value)


def check_real(name: str, value: object, *, low: float | None = None, strict: bool = False,
               high: float | None = None) -> float:
    """``value`` as a finite ``float`` within ``[low, high]`` (``(low, high]`` if ``strict``).

    Raises:
        InputError: If it is not a finite number in that range, naming ``name``.
    """
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"{name}: must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{name}: must be finite, got {value!r}")
    if low is not None and (v <= low if strict else v < low):
        bound = "greater than" if strict else "at least"
        raise InputError(f"{name}: must be {bound} {low}, got {value!r}")
    if high is not None and v > high:
        raise InputError(f"{name}: must be at most {high}, got {value!r}")
    return v


@dataclass(frozen=True)
class Option:
    """One option: its name, default, kind, range and what it means (with its unit).

    Attributes:
        name: The keyword argument; the flag is ``--`` and the name with dashes.
        default: The default value (``None``: not set, see ``help``).
        kind: ``"int"``, ``"real"`` or ``"choice"``.
        help: What it sets, with its unit; the command line appends the default.
        low: Smallest value allowed (``None``: no bound).
        high: Largest value allowed (``None``: no bound).
        strict: ``low`` itself is not allowed.
        choices: The values of a ``"choice"`` option.
        optional: ``None`` is a value (it means what ``help`` says).
    """

    name: str
    default: Any
    kind: str
    help: str
    low: float | None = None
    high: float | None = None
    strict: bool = False
    choices: tuple[str, ...] = ()
    optional: bool = False

    def __repr__(self) -> str:
        return f"Option({self.name}={self.default!r})"

    @property
    def flag(self) -> str:
        """The command-line flag, kebab-case."""
        return "--" + self.name.replace("_", "-")

    def check(self, value: object) -> Any:
        """``value`` checked and converted (``int``, ``float`` or one of the choices).

        Raises:
            InputError: If it is out of range or of the wrong type, naming the option.
        """
        if value is None and self.optional:
            return None
        if self.kind == "choice":
            if value not in self.choices:
                raise InputError(f"{self.name}: must be one of {', '.join(self.choices)}, got "
                                 f"{value!r}")
            return value
        if self.kind == "int":
            value = (check_positive_int if self.low == 1 else check_non_negative_int)(
                self.name, value)
            if self.high is not None and value > self.high:
                raise InputError(f"{self.name}: must be at most {self.high:g}, got {value}")
            return value
        return check_real(self.name, value, low=self.low, strict=self.strict, high=self.high)

    def parse(self, text: str) -> Any:
        """The value of the command-line text ``text``, checked (an argparse ``type``).

        Raises:
            InputError: If it is not a value of this option, naming the flag.
        """
        try:
            value = int(text) if self.kind == "int" else float(text)
        except ValueError:
            what = {"int": "a positive integer" if self.low == 1 else "a non-negative integer",
                    "real": "a number"}[self.kind]
            raise InputError(f"{self.flag}: expected {what}, got {text!r}") from None
        try:
            return self.check(value)
        except InputError as exc:
            raise InputError(f"{self.flag}:{str(exc).partition(':')[2]}") from None


_OPTIONS = (
    Option("resolution", 64, "int", "cells along the longest side of the domain", low=1),
    Option("iterations", None, "int", "iterations of the flow (none: 300 up to resolution 64, "
           "then 300 * 64 / resolution, at least 50, the start being solved coarse to fine)",
           low=1, optional=True),
    Option("alpha", 0.01, "real", "weight of the smoothness (surface area) term", low=0.0,
           high=MAX_ALPHA),
    Option("start", STARTS[0], "choice", "starting surface: implicit (any shape, fitted to the "
           "data coarse to fine), height (a height field over the plane through the points) "
           "or paper (that plane, bent by --bulge)", choices=STARTS),
    Option("bulge", 0.0, "real", "with start paper or height: bend the initial plane toward "
           "the cameras by this times the distance to the nearest point (paper eq. 23)",
           low=-MAX_BULGE, high=MAX_BULGE),
    Option("bulge_cap", None, "real", "cap on that distance, in voxel widths (none: no cap)",
           low=0.0, strict=True, optional=True),
    Option("reinit_every", 10, "int", "reinitialise to a signed distance every N iterations, "
           "0 never", low=0),
    Option("point_weight", 0.02, "real", "rate w_P of the point term, in units of 1/h^2",
           low=0.0),
    Option("gaussian_width", 1.0, "real", "standard deviation of the point Gaussians, in "
           "voxel widths", low=0.0, strict=True),
    Option("normal_radius", 1.0, "real", "radius r_N of the balls that carry the constraint "
           "normals, in voxel widths", low=0.0, strict=True),
    Option("cfl", 0.9, "real", "time step as a fraction of the parabolic limit "
           "h^2 / (6 (1 + alpha))", low=0.0, strict=True, high=1.0),
    Option("fit_iterations", 5, "int", "rounds of the height-field fit of start height", low=0),
    Option("fit_degree", 4, "int", "highest total degree of that height field", low=1),
    Option("margin", 0.2, "real", "margin around the points when the scene gives no domain, "
           "as a fraction of their longest extent", low=0.0),
    Option("narrow_band", 4.0, "real", "update only the nodes within this many voxel widths "
           "of the zero set (none: every node)", low=3.0, optional=True),
    Option("measure_every", 0, "int", "record the measures every N iterations (0: only the "
           "start and the last)", low=0),
)

OPTIONS: dict[str, Option] = {o.name: o for o in _OPTIONS}
"""The options of a reconstruction by name."""

DEFAULTS: dict[str, Any] = {o.name: o.default for o in _OPTIONS}
"""Their defaults by name."""

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
