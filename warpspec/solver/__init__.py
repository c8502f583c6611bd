"""The solver: device arrays, a narrow-band tracker, pluggable starts and the orchestrator.

- :mod:`.workspace`: the device arrays of one grid and the passes that fill them;
- :mod:`.tracker`: the narrow band, reinitialisation and rollback;
- :mod:`.starts`: the starting surfaces (the paper's plane and bend, the height field, the
  implicit fit, a level set handed in);
- :mod:`.state`: :class:`Result` and the level-set files;
- :mod:`.reconstructor`: :class:`Reconstructor` and :func:`reconstruct`.
"""

from .reconstructor import MEASURE_KEYS, Reconstructor, reconstruct
from .starts import initial_plane
from .state import Result, load_state, save_state, write_state
from .tracker import FULL_REINIT_EVERY

__all__ = [
    "FULL_REINIT_EVERY",
    "MEASURE_KEYS",
    "Reconstructor",
    "Result",
    "initial_plane",
    "load_state",
    "reconstruct",
    "save_state",
    "write_state",
]
