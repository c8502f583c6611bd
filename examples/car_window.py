"""Look-alike of the paper's car window (section 4.1): a gently curved pane in the sun.

A patch of a cylinder of radius 2 (1.0 wide, 0.6 high, tilted 30 degrees), 38 highlights of a
directional sun (one camera each), 2 point constraints at diagonal corners. As in the paper,
the start is the plane through the points bent toward the cameras with c = 0.3 and the
distance capped at d_max = 3 voxels (``car-window-paper``); warpspec's default then fits its
height field to the normals before the flow (``car-window``).

Writes ``car_window_fig4.png`` (starts, truth, results) and ``car_window_fig5.png``
(convergence) in ``--out-dir`` and prints the results-table rows (markdown). Example:

    python examples/car_window.py --resolution 64 --iterations 300
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from experiments import scene_example  # noqa: E402


def main(argv: Sequence[str] | None = None) -> int:
    return scene_example(["car-window-paper", "car-window"], __doc__.splitlines()[0], argv=argv)


if __name__ == "__main__":
    raise SystemExit(main())
