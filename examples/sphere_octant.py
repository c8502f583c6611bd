"""The paper's synthetic experiment (section 4.2): one eighth of a sphere from sparse data.

24 normal constraints (highlights of a directional light, one camera each), 3 point
constraints at the octant's corners, Gaussian of one cell, alpha = 0.01, 300 iterations.
Two starts are compared:

- ``octant-paper``: the paper's start, the plane through the 3 points bent with c = 0.5;
- ``octant``: warpspec's default, the same bent plane refined by a height field fitted to the
  points and to the normals where the rays meet it (``fit_iterations=5``).

With ``--noise PX`` (default 0.5; 0 skips it) the fitted start is also run on highlights with
Gaussian pixel noise.

Writes, in ``--out-dir``:

- ``octant_fig4.png``: Figure 4: the initial plane, the bent start, the truth, the result
  from the paper's start, the fitted start and its result (coloured by the distance to the
  truth in voxel widths);
- ``octant_fig5.png``: Figure 5: mean 1 - N.n and mean |phi(S)| per iteration, each run.

Prints the results-table row of each run, the diagnostics and the accuracy table of the
default run, as markdown. Example:

    python examples/sphere_octant.py --resolution 64 --iterations 300
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from experiments import scene_example  # noqa: E402


def main(argv: Sequence[str] | None = None) -> int:
    return scene_example(["octant-paper", "octant", "octant-noise"], __doc__.splitlines()[0],
                         argv=argv, noise_flag=True)


if __name__ == "__main__":
    raise SystemExit(main())
