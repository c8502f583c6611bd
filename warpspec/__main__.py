"""``python -m warpspec``: the command line."""

from .cli import entry

entry()
