"""Calibrate the standard errors of the default's scale selection on noisy smooth shapes.

For every rung of the ladder (curvature.fitting.scale_selection) and every top, this
fits anchors of noisy planes, spheres and cylinders and compares the RMS error of k1 and k2 with
the uncalibrated standard error d / (h^2 sqrt(s)) of the same fits. The ratio is the
calibration constant of that rung (RUNGS and TOPS in scale_selection.py).

    python benchmarks/calibrate_scales.py [--n 20000] [--anchors 2000]
"""

from __future__ import annotations

import argparse

import numpy as np

from curvature import synthetic
from curvature.estimators.auto import knn_csr
from curvature.fitting.normal_field import nfr_anchor_fits_one, pca_normals
from curvature.fitting.normal_quadric import N_QUAD
from curvature.fitting.scale_selection import (
    KIND_MONGE_RIDGE,
    KIND_NORMAL_QUADRIC,
    RUNGS,
    TOP_POINTS,
    TOPS,
    ladder_estimates,
)
from curvature.neighborhoods.kdtree import build_tree


def rung_errors(cloud, anchors: int, normal_k: int = 48, seed: int = 0):
    """Per rung of pass 2 and per top: (RMS error, RMS of d / (h^2 sqrt(s))) over anchors."""
    pts = cloud.points
    tree = build_tree(pts)
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(np.flatnonzero(cloud.interior), anchors, replace=False))
    allq = np.arange(pts.shape[0], dtype=np.int64)
    field = np.empty((pts.shape[0], 3))
    indptr, indices, _ = knn_csr(pts, tree, allq, normal_k)
    pca_normals(pts, allq, indptr, indices, field)
    tops = [t[0] for t in TOPS["fit"]]
    indptr, indices, _ = knn_csr(pts, tree, idx.astype(np.int64), max(tops))
    ladder = np.asarray([r[0] for r in RUNGS["fit"]], np.int64)
    kinds = np.asarray([r[1] for r in RUNGS["fit"]], np.int64)
    levels = ladder.size
    rows = levels + len(tops)
    err = [[] for _ in range(rows)]
    pred = [[] for _ in range(rows)]
    coef, quad, frame = np.empty((2, 10)), np.empty(N_QUAD), np.empty((3, 3))
    one = [np.empty(1), np.empty(1), np.empty(1, np.int8), np.empty(1), np.empty(1, np.int8)]
    for j, p in enumerate(idx):
        nbr = indices[indptr[j]:indptr[j + 1]]
        quads, est = np.empty((levels, N_QUAD)), np.empty((rows, 8))
        ladder_estimates(pts, field, p, nbr, ladder, kinds, quads, est)
        counts = list(ladder)
        for t, size in enumerate(tops):
            stride = max(1, size // TOP_POINTS)
            sub = nbr[:size:stride]
            fk1, fk2, fd, fh, fm, _ = nfr_anchor_fits_one(pts, field, p, sub, 0.7, coef, quad,
                                                       frame, 0, one[0], one[1], one[2],
                                                       one[3], one[4])
            est[levels + t] = (1.0 if one[4][0] == 0 else 0.0, fk1, fk2, fd, fh, fh, 1.0, fm)
            counts.append(sub.shape[0])
        sign = 1.0 if np.dot(field[p], cloud.normals[p]) >= 0 else -1.0
        t1, t2 = (cloud.k1[p], cloud.k2[p]) if sign > 0 else (-cloud.k2[p], -cloud.k1[p])
        for li in range(rows):
            if est[li, 0] != 1.0:
                continue
            err[li].append(np.hypot(est[li, 1] - t1, est[li, 2] - t2) / np.sqrt(2.0))
            pred[li].append(est[li, 3] / (est[li, 5] ** 2 * np.sqrt(counts[li])))
    return [(float(np.sqrt(np.mean(np.square(e)))), float(np.sqrt(np.mean(np.square(q)))))
            for e, q in zip(err, pred, strict=True)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--anchors", type=int, default=1500)
    args = parser.parse_args()
    kind_names = {KIND_NORMAL_QUADRIC: "nquad", KIND_MONGE_RIDGE: "ridge"}
    names = [f"{s}/{kind_names.get(k, 'monge')}" for s, k, _ in RUNGS["fit"]]
    names += [f"top/{s}" for s, _ in TOPS["fit"]]
    print("shape      noise  " + "  ".join(f"{n:>14}" for n in names))
    for shape in ("plane", "sphere", "cylinder"):
        for noise in (0.1, 0.25, 0.5):
            cloud = synthetic.make(shape, args.n, noise=noise, seed=3)
            rows = rung_errors(cloud, args.anchors)
            print(f"{shape:9} {noise:6} " + "  ".join(f"{e / q:6.2f} ({e:5.3f})"
                                                   for e, q in rows), flush=True)


if __name__ == "__main__":
    main()
