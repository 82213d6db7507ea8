"""``curvature synthetic SHAPE ...``: sample a shape and write it (``curvature synthetic -h``)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..io import write
from .base import NOISE_MODELS, SAMPLINGS
from .parts import PART_SHAPES
from .shapes import SHAPES, make


def main(argv=None) -> int:
    """``curvature synthetic SHAPE --n N --noise PCT ... -o OUT``.

    Writes the (noisy) points and exact normals with :func:`curvature.write`; an ``.npy``
    output holds only the (n, 3) points, saved with :func:`numpy.save`.
    """
    parser = argparse.ArgumentParser(
        prog="curvature synthetic",
        description="Sample an analytic test shape (exact curvature known) and write it.",
    )
    parser.add_argument("shape", choices=sorted(SHAPES), help="shape to sample")
    parser.add_argument("--n", type=int, default=10000, help="number of points (10000)")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="noise std in percent of the bounding-box diagonal (0)")
    parser.add_argument("--noise-model", choices=NOISE_MODELS, default="axis",
                        help="per-axis Gaussian, or random direction times Gaussian (axis)")
    parser.add_argument("--sampling", choices=SAMPLINGS, default="area",
                        help="area-uniform or parameter-uniform sampling (area; part shapes "
                             "are always area-uniform)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    parser.add_argument("-o", "--output", required=True,
                        help="output file (.ply, .csv, .npz, ...; .npy saves the points only)")
    args = parser.parse_args(argv)
    try:
        options = {} if args.shape in PART_SHAPES else {"sampling": args.sampling}
        cloud = make(args.shape, args.n, noise=args.noise, noise_model=args.noise_model,
                     seed=args.seed, **options)
        if str(args.output).lower().endswith(".npy"):
            np.save(args.output, cloud.points)
        else:
            write(args.output, cloud.to_point_cloud())
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(cloud)} points ({cloud.name}, noise {cloud.noise}% BBD = "
          f"{cloud.noise_sigma:.6g}, {cloud.noise_model}) to {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
