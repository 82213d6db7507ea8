"""Vertex graph of a triangle mesh: our numba ``face_graph`` against trimesh's unique edges.

Issue 19 asks to use trimesh for mesh connectivity where it serves better. Both give the same
symmetric vertex graph (checked here); the script prints the median time of each over
interleaved runs and their ratio.

    python benchmarks/mesh_graph.py [--subdivisions 7] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

from curvature.neighborhoods.connectivity import edges_to_csr, face_graph


def with_trimesh(points: np.ndarray, faces: np.ndarray):
    """CSR vertex graph from trimesh's unique edges (the mesh object built without
    processing, so vertices keep their order)."""
    mesh = trimesh.Trimesh(points, faces, process=False)
    edges = mesh.edges_unique
    return edges_to_csr(edges[:, 0].astype(np.int64), edges[:, 1].astype(np.int64),
                        len(points))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    sphere = trimesh.creation.icosphere(subdivisions=args.subdivisions)
    points, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces, np.int64)
    ours, theirs = face_graph(faces, len(points)), with_trimesh(points, faces)
    assert all(np.array_equal(a, b) for a, b in zip(ours, theirs, strict=True))
    times = {"face_graph": [], "trimesh edges_unique": []}
    for _ in range(args.repeats):
        for name, fn in (("face_graph", lambda: face_graph(faces, len(points))),
                         ("trimesh edges_unique", lambda: with_trimesh(points, faces))):
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    base = np.median(times["face_graph"])
    print(f"{len(points):,} vertices, {len(faces):,} triangles, {args.repeats} runs each")
    for name, ts in times.items():
        print(f"{name:22s} median {np.median(ts):.3f} s  ({np.median(ts) / base:.2f} x ours)")


if __name__ == "__main__":
    main()
