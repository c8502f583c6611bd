"""Look-alike of the paper's wine bottle (section 4.1): glass between labels, camera flash.

A cylinder of radius 4 cm; the patch between the labels spans +-45 degrees and heights 11 to
19 cm. Eleven views along a rising arc, each lit by its own flash, so each highlight is where
the surface faces the camera; 4 point constraints at the label corners. Two starts: the plane
through the points (``wine-bottle-paper``) and warpspec's default, that plane refined by a
height field fitted to the normals (``wine-bottle``).

Writes ``wine_bottle_fig4.png`` (starts, truth, results) and ``wine_bottle_fig5.png``
(convergence) in ``--out-dir`` and prints the results-table rows (markdown). Example:

    python examples/wine_bottle.py --resolution 64 --iterations 300
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from experiments import scene_example  # noqa: E402


def main(argv: Sequence[str] | None = None) -> int:
    return scene_example(["wine-bottle-paper", "wine-bottle"], __doc__.splitlines()[0],
                         argv=argv)


if __name__ == "__main__":
    raise SystemExit(main())
