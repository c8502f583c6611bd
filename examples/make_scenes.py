"""Write the built-in synthetic scenes to scene files, with their ground truth.

For each scene NAME this writes, in the output folder:

- NAME.json: the scene (version-1 format, DESIGN section 10), ready for ``warpspec``;
- NAME.truth.json: the true specular points and normals, camera centres and intrinsics;
- NAME.ply: the truth mesh (the surface cut to the scene's patch), unless --no-meshes.

Examples:
    python examples/make_scenes.py                      # all scenes into examples/scenes/
    python examples/make_scenes.py --scenes octant --noise 0.5 --seed 3 --suffix -noisy
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from warpspec.synthetic import make_scene, scene_names

# Truth meshes written next to the scenes: fine enough for evaluation at the usual grid
# resolutions, small enough to keep the folder well under 1 MB.
PLY_OPTIONS = {
    "octant": {"subdivisions": 5},
    "car-window": {"sections": 24},
    "wine-bottle": {"sections": 32},
    "ellipsoid-cap": {"subdivisions": 4},
    "paraboloid": {"resolution": 32},
    "saddle": {"resolution": 32},
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, default=Path(__file__).parent / "scenes",
                        help="folder to write into (default: examples/scenes next to this file)")
    parser.add_argument("--scenes", nargs="+", default=scene_names(), choices=scene_names(),
                        metavar="NAME", help=f"scenes to write (default: all of {scene_names()})")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="pixel noise standard deviation in pixels (default: 0)")
    parser.add_argument("--outliers", type=float, default=0.0,
                        help="fraction of specularities replaced by random pixels (default: 0)")
    parser.add_argument("--point-noise", type=float, default=0.0,
                        help="noise on each coordinate of the 3D points, in voxels of the "
                             "default grid (default: 0)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise and outliers")
    parser.add_argument("--suffix", default="", help="appended to each file name")
    parser.add_argument("--no-meshes", action="store_true", help="do not write the .ply meshes")
    args = parser.parse_args(argv)

    args.out_dir.mkdir(parents=True, exist_ok=True)
    for name in args.scenes:
        scene = make_scene(name, noise=args.noise, outliers=args.outliers, seed=args.seed,
                           point_noise=args.point_noise)
        stem = args.out_dir / f"{name}{args.suffix}"
        scene.to_json(stem.with_suffix(".json"))
        truth = stem.parent / f"{stem.name}.truth.json"
        truth.write_text(json.dumps(scene.truth_dict(), indent=1) + "\n")
        written = [stem.with_suffix(".json").name, truth.name]
        if not args.no_meshes:
            mesh = scene.truth_mesh(**PLY_OPTIONS.get(name, {}))
            mesh.export(stem.with_suffix(".ply"))
            written.append(stem.with_suffix(".ply").name)
        print(f"{name}: {len(scene.truth_points)} specularities, {len(scene.cameras)} cameras, "
              f"{len(scene.points)} points -> {', '.join(written)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
