"""Mesh rings (DESIGN.md 4.3): face connectivity, tangent-plane Delaunay, ring growth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay

from curvature.errors import CurvatureInputError, ParameterError
from curvature.neighborhoods import FINDERS, neighbors
from curvature.neighborhoods.connectivity import tangent_delaunay, voronoi_neighbors
from curvature.neighborhoods.kdtree import build_tree
from curvature.neighborhoods.mesh import MeshFinder

BUNNY = Path("/work/shared/data/bun_zipper.ply")


def read_ascii_ply(path):
    """Vertices (n, 3) and triangles (m, 3) of an ascii PLY with x y z first."""
    lines = path.read_text().splitlines()
    end = lines.index("end_header")
    nv = nf = 0
    nprops = 0
    for line in lines[:end]:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            nv = int(words[2])
        elif words[:2] == ["element", "face"]:
            nf = int(words[2])
        elif words[:1] == ["property"] and nf == 0:
            nprops += 1
    body = lines[end + 1:]
    verts = np.array(" ".join(body[:nv]).split(), float).reshape(nv, nprops)[:, :3]
    faces = np.array(" ".join(body[nv:nv + nf]).split(), np.int64).reshape(nf, 4)
    assert np.all(faces[:, 0] == 3)
    return verts, faces[:, 1:]


@pytest.fixture(scope="module")
def bunny():
    if not BUNNY.exists():
        pytest.skip("bunny scan not available")
    verts, faces = read_ascii_ply(BUNNY)
    assert verts.shape == (35947, 3) and faces.shape == (69451, 3)
    return verts, faces


def ref_adjacency(faces, n):
    adj = [set() for _ in range(n)]
    for a, b, c in faces.tolist():
        for u, v in ((a, b), (b, c), (c, a)):
            if u != v:
                adj[u].add(v)
                adj[v].add(u)
    return [sorted(s) for s in adj]


def ref_rings(adj, p, min_neighbors):
    """Whole rings, breadth first, until min_neighbors or the component is exhausted."""
    seen, out, frontier = {p}, [], [p]
    while len(out) < min_neighbors:
        ring = []
        for u in frontier:
            for v in adj[u]:
                if v not in seen:
                    seen.add(v)
                    ring.append(v)
        if not ring:
            break
        out += ring
        frontier = ring
    return out


def test_registered():
    assert FINDERS["mesh"] is MeshFinder


# ---------------------------------------------------------------- with faces


def test_bunny_one_ring_is_the_edge_neighbors(bunny):
    verts, faces = bunny
    adj = ref_adjacency(faces, len(verts))
    sample = np.random.default_rng(0).choice(len(verts), 3000, replace=False)
    nb = MeshFinder(verts, faces=faces, min_neighbors=1).query(sample)
    for j, p in enumerate(sample):
        assert nb[j].tolist() == adj[p]
    degrees = np.array([len(a) for a in adj])
    assert 5.5 < degrees[degrees > 0].mean() < 6.5


@pytest.mark.parametrize("min_neighbors", [10, 40])
def test_bunny_rings_grow(bunny, min_neighbors):
    verts, faces = bunny
    adj = ref_adjacency(faces, len(verts))
    sample = np.random.default_rng(1).choice(len(verts), 2000, replace=False)
    finder = MeshFinder(verts, faces=faces, min_neighbors=min_neighbors)
    nb = finder.query(sample)
    for j, p in enumerate(sample):
        assert nb[j].tolist() == ref_rings(adj, p, min_neighbors)
    sizes = nb.sizes()
    # the scan has one big component and 1,113 vertices used by no face
    isolated = np.array([len(adj[p]) == 0 for p in sample])
    assert np.all(sizes[isolated] == 0)
    assert np.all(sizes[~isolated] >= min_neighbors)
    # the 2-ring (and beyond) is really reached: a 1-ring alone is never 40 points here
    if min_neighbors == 40:
        one_ring = np.array([len(adj[p]) for p in sample])
        assert np.all(sizes[~isolated] > one_ring[~isolated])


def test_bunny_whole_cloud_and_chunks(bunny):
    verts, faces = bunny
    whole = neighbors(verts, "mesh", faces=faces)
    assert len(whole) == len(verts)
    finder = MeshFinder(verts, faces=faces)
    order = np.random.default_rng(2).permutation(len(verts))
    for workers in (1, 2):
        for chunk in np.array_split(order, 4):
            part = finder.query(chunk, workers=workers)
            for j in range(0, chunk.size, 37):
                assert np.array_equal(part[j], whole[chunk[j]])


def test_component_exhausted_and_isolated_vertex():
    pts = np.random.default_rng(3).normal(size=(7, 3))
    faces = np.array([[0, 1, 2], [3, 4, 5], [3, 5, 5]])  # two triangles; 6 is isolated
    nb = MeshFinder(pts, faces=faces, min_neighbors=10).query(np.arange(7))
    assert nb[0].tolist() == [1, 2]
    assert nb[4].tolist() == [3, 5]
    assert nb[6].tolist() == []


def test_ring_order_on_a_strip():
    # a triangle strip 0-1-2-...-9: rings from vertex 0 are {1, 2}, {3, 4}, ...
    faces = np.array([[i, i + 1, i + 2] for i in range(8)])
    pts = np.c_[np.arange(10.0), np.arange(10.0) % 2, np.zeros(10)]
    assert MeshFinder(pts, faces=faces, min_neighbors=3).query(np.array([0]))[0].tolist() == [
        1, 2, 3, 4]
    assert MeshFinder(pts, faces=faces, min_neighbors=2).query(np.array([0]))[0].tolist() == [
        1, 2]


def test_bad_faces():
    pts = np.zeros((5, 3))
    with pytest.raises(CurvatureInputError, match="outside 0..4"):
        MeshFinder(pts, faces=np.array([[0, 1, 7]]))


# ---------------------------------------------------------------- without faces


def test_voronoi_neighbors_match_scipy():
    rng = np.random.default_rng(4)
    k = 16
    buf = [np.empty(k + 5) for _ in range(3)] + [np.empty(k + 5, np.int64)]
    wbuf = [np.empty(k + 5) for _ in range(2)] + [np.empty(k + 5, np.int64)]
    for trial in range(300):
        y = rng.normal(size=(k, 2)) * [1.0, 0.2 + trial % 5]
        if trial % 3 == 0:
            y[:, 0] = np.abs(y[:, 0]) + 0.01  # the point is on the hull of its neighborhood
        flags = np.zeros(k, bool)
        voronoi_neighbors(np.ascontiguousarray(y[:, 0]), np.ascontiguousarray(y[:, 1]), flags,
                          buf[0], buf[1], buf[3], buf[2], wbuf[0], wbuf[1], wbuf[2])
        tri = Delaunay(np.vstack([[0.0, 0.0], y]))
        ptr, ind = tri.vertex_neighbor_vertices
        expected = sorted(int(v) - 1 for v in ind[ptr[0]:ptr[1]])
        assert np.flatnonzero(flags).tolist() == expected, trial


@pytest.fixture(scope="module")
def flat():
    rng = np.random.default_rng(5)
    pts = np.c_[rng.uniform(0, 1, (5000, 2)), np.zeros(5000)]
    inner = np.flatnonzero(np.all((pts[:, :2] > 0.1) & (pts[:, :2] < 0.9), axis=1))
    return pts, inner


def test_local_delaunay_is_delaunay_of_the_neighborhood(flat):
    pts, inner = flat
    nbr, flags = tangent_delaunay(pts, build_tree(pts), 16, idx=inner)
    for j in range(0, inner.size, 3):
        p = inner[j]
        local = np.r_[p, nbr[j]]
        ptr, ind = Delaunay(pts[local, :2]).vertex_neighbor_vertices
        assert set(local[ind[ptr[0]:ptr[1]]].tolist()) == set(nbr[j][flags[j]].tolist())


def test_cloud_connectivity_symmetric_about_six(flat):
    pts, inner = flat
    finder = MeshFinder(pts, min_neighbors=1)
    indptr, indices = finder.graph()
    n = len(pts)
    rows = np.repeat(np.arange(n), np.diff(indptr))
    forward = set(zip(rows.tolist(), indices.tolist(), strict=True))
    assert all((b, a) in forward for a, b in forward)
    degree = np.diff(indptr)
    assert abs(degree[inner].mean() - 6.0) < 0.3
    # the 1-ring of the finder is the graph row
    nb = finder.query(inner)
    for j in range(0, inner.size, 11):
        assert nb[j].tolist() == indices[indptr[inner[j]]:indptr[inner[j] + 1]].tolist()
    # close to the global Delaunay triangulation (a 16-point window misses some long edges)
    ptr, ind = Delaunay(pts[:, :2]).vertex_neighbor_vertices
    same = [set(ind[ptr[p]:ptr[p + 1]].tolist()) == set(indices[indptr[p]:indptr[p + 1]].tolist())
            for p in inner]
    assert np.mean(same) > 0.85


def test_tilted_plane_gives_the_same_graph(flat):
    pts, _ = flat
    q, _ = np.linalg.qr(np.random.default_rng(6).normal(size=(3, 3)))
    a = MeshFinder(pts).graph()
    b = MeshFinder(pts @ q.T + [3.0, -1.0, 2.0]).graph()
    da, db = np.diff(a[0]), np.diff(b[0])
    same = [np.array_equal(a[1][a[0][p]:a[0][p + 1]], b[1][b[0][p]:b[0][p + 1]])
            for p in range(len(pts))]
    assert np.mean(same) > 0.99 and abs(da.mean() - db.mean()) < 0.01


def torus(n, seed=0, R=2.0, r=1.0):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 2 * np.pi, (2, n))
    return np.c_[(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)]


def test_torus_rings_and_workers():
    pts = torus(5000)
    whole = neighbors(pts, "mesh")
    assert whole.sizes().min() >= 10
    finder = MeshFinder(pts)
    order = np.random.default_rng(7).permutation(5000)
    for workers in (1, 2):
        for chunk in np.array_split(order, 3):
            part = finder.query(chunk, workers=workers)
            for j, p in enumerate(chunk):
                assert np.array_equal(part[j], whole[p])
    indptr, indices = MeshFinder(pts).graph(workers=2)
    assert np.array_equal(indptr, finder.graph()[0])
    assert np.array_equal(indices, finder.graph()[1])


@pytest.mark.parametrize("params, message", [
    (dict(min_neighbors=0), "method 'mesh': parameter 'min_neighbors' must be >= 1"),
    (dict(k_delaunay=2), "method 'mesh': parameter 'k_delaunay' must be >= 3"),
    (dict(k=5), "unknown parameter(s) ['k']"),
])
def test_parameter_errors(params, message):
    with pytest.raises(ParameterError) as err:
        MeshFinder(torus(20), **params)
    assert message in str(err.value)
