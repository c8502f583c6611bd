"""warpspec: shape from specularities with sparse data, as a level-set solver in NVIDIA Warp.

The method is the variational level-set flow of Solem, Aanaes and Heyden (3DPVT 2004): the
smoothest surface through a few known points whose normals, where the specular rays meet it,
obey the law of reflection.
"""

from .colmap import load_colmap
from .detect import detect_highlights
from .errors import InputError, ReconstructionError, SceneError
from .grid import Grid
from .redistance import point_distance, redistance
from .scene import Light, Scene, SceneWarning
from .solver import Reconstructor, Result, reconstruct
from .verdict import Verdict

__version__ = "0.1.0"

__all__ = [
    "Grid",
    "InputError",
    "Light",
    "ReconstructionError",
    "Reconstructor",
    "Result",
    "Scene",
    "SceneError",
    "SceneWarning",
    "Verdict",
    "__version__",
    "detect_highlights",
    "load_colmap",
    "point_distance",
    "reconstruct",
    "redistance",
]
