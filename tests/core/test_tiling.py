"""Tiled runs equal untiled runs bit for bit, for every method; halos grow when short."""

from __future__ import annotations

import numpy as np
import pytest

import curvature
from curvature import synthetic
from curvature.neighborhoods.kdtree import build_tree
from curvature.pipeline import tiling
from curvature.pipeline.block import compute_block
from curvature.pipeline.request import resolve_request


def assert_identical(a, b):
    for name, arr in a.fields().items():
        np.testing.assert_array_equal(b.fields()[name], arr, err_msg=name)


@pytest.fixture(scope="module")
def torus():
    return synthetic.torus(8000, noise=0.3, seed=1).points


CASES = [
    ("auto", {}), ("knn", {"fit": "implicit"}), ("knn", {"fit": "monge", "k": 16}),
    ("knn", {"fit": "nfr", "k": 64, "normal_k": 24}), ("tc", {"fit": "implicit"}),
    ("tc", {"fit": "monge", "min_neighbors": 24}), ("egg", {"fit": "monge"}), ("mesh", {}),
]


@pytest.mark.parametrize("method, kwargs", CASES, ids=[f"{m}-{k}" for m, k in CASES])
def test_tiled_equals_untiled(torus, method, kwargs):
    whole = curvature.estimate(torus, method, tile_points=0, **kwargs)
    for tile_points in (1500, 4000):
        tiled = curvature.estimate(torus, method, tile_points=tile_points, **kwargs)
        assert tiled.info["tiles"] == -(-len(torus) // tile_points)
        assert_identical(whole, tiled)


def test_clean_cloud_auto_and_given_normals(torus):
    cloud = synthetic.ellipsoid(6000, axes=(3, 2, 1), seed=2)
    whole = curvature.estimate(cloud.points, normals=cloud.normals, tile_points=0)
    tiled = curvature.estimate(cloud.points, normals=cloud.normals, tile_points=1000)
    assert tiled.info["fit"] == "implicit" and tiled.info["tiles"] == 6
    assert_identical(whole, tiled)


def test_mesh_with_faces_on_the_bunny(shared_data):
    mesh = curvature.read(shared_data / "bun_zipper.ply")
    whole = curvature.estimate(mesh, "mesh", fit="monge", tile_points=0)
    tiled = curvature.estimate(mesh, "mesh", fit="monge", tile_points=5000)
    assert tiled.info["tiles"] == 8
    assert_identical(whole, tiled)
    np.testing.assert_array_equal(tiled.faces, mesh.faces)


def test_short_halos_grow_and_results_stay_identical(torus, monkeypatch):
    monkeypatch.setattr(tiling, "HALO_MARGIN", 0.05)
    monkeypatch.setattr(tiling, "AUTO_HALO", 0.5)
    for method, kwargs in (("auto", {}), ("tc", {}), ("knn", {"fit": "nfr", "k": 48})):
        whole = curvature.estimate(torus, method, tile_points=0, **kwargs)
        tiled = curvature.estimate(torus, method, tile_points=2000, **kwargs)
        assert tiled.info["regrown"] > 0, method
        assert_identical(whole, tiled)


def test_the_default_halo_covers_its_reach_without_recomputing(torus):
    # The guess is in fit radii: measured, or from the spacing on an even cloud.
    def guess(k, radius=np.nan):
        req = resolve_request(None, None, None, {"k": k}, None, None, None, 1, 1000)
        return tiling.halo_guess(req, 0.01, radius)

    assert guess(768, 0.05) == pytest.approx(tiling.AUTO_HALO * 0.05)
    assert guess(768) == pytest.approx(np.sqrt(2.0) * guess(384))
    assert guess(768) == pytest.approx(tiling.AUTO_HALO * np.sqrt(768 / 24) * 0.01)
    spts = np.ascontiguousarray(torus)
    radius = tiling.fit_radius(spts, build_tree(spts), 96)
    d = np.sort(np.linalg.norm(spts[:, None] - spts[None, ::97], axis=2), axis=0)[96]
    assert np.min(d) <= radius <= np.max(d)  # a distance to the 96th neighbor
    # A halo of 16 spacings was computed twice on every tile of a noisy torus (issue 21).
    res = curvature.estimate(torus, tile_points=2000)
    assert res.info["tiles"] > 2 and res.info["regrown"] == 0


def test_tiles_are_identical_for_any_workers_and_order(torus):
    ref = curvature.estimate(torus, tile_points=3000, workers=1)
    perm = np.random.default_rng(3).permutation(len(torus))
    other = curvature.estimate(torus[perm], tile_points=2500, workers=2, chunk_size=700)
    for name, arr in ref.fields().items():
        np.testing.assert_array_equal(other.fields()[name], arr[perm], err_msg=name)


def test_reach_of_knn_is_the_kth_distance(torus):
    req = resolve_request(None, "knn", "monge", {"k": 12}, None, None, None, 1, 1000)
    spts = np.ascontiguousarray(torus[:2000])
    block = compute_block(spts, None, req, track_reach=True)
    d = np.linalg.norm(spts[:, None, :] - spts[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    np.testing.assert_allclose(block.reach, np.sort(d, axis=1)[:, 11], rtol=1e-12)


def test_restrict_graph_keeps_edges_inside():
    indptr = np.array([0, 2, 4, 6, 8])
    indices = np.array([1, 3, 0, 2, 1, 3, 0, 2])  # a 4-cycle 0-1-2-3-0
    ptr, idx = tiling.restrict_graph((indptr, indices), np.array([0, 1, 3]), 4)
    assert ptr.tolist() == [0, 2, 3, 4]
    assert idx.tolist() == [1, 2, 0, 0]


@pytest.mark.parametrize("bad", [-1, 2.5, True, "many"])
def test_bad_tile_points(torus, bad):
    with pytest.raises(curvature.ParameterError, match="tile_points"):
        curvature.estimate(torus[:100], "knn", tile_points=bad)


# -- executors --------------------------------------------------------------------------------

class RecordingExecutor:
    """A thread pool that records submissions and can fail one tile or cancel a run."""

    def __init__(self, fail_tile=None):
        from concurrent.futures import ThreadPoolExecutor

        self.pool = ThreadPoolExecutor(2)
        self.submitted: list[int] = []
        self.futures = []
        self.fail_tile = fail_tile

    def submit(self, fn, inp):
        self.submitted.append(inp.tile.index)
        if inp.tile.index == self.fail_tile:
            future = self.pool.submit(_fail, inp.tile.index)
        else:
            future = self.pool.submit(fn, inp)
        self.futures.append(future)
        return future


def _fail(index):
    raise RuntimeError(f"tile {index} failed on the worker")


def test_executor_runs_equal_local_runs_for_any_pool(torus):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    whole = curvature.estimate(torus, tile_points=0)
    recorder = RecordingExecutor()
    threads = curvature.estimate(torus, tile_points=1000, executor=recorder)
    # every tile went out (some twice, when their first halo was short)
    assert set(recorder.submitted) == set(range(8)) and threads.info["tiles"] == 8
    assert len(recorder.submitted) == 8 + threads.info["regrown"]
    assert_identical(whole, threads)
    # numba's OpenMP layer forbids fork() after it started; a fork server is clean
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("forkserver")) as pool:
        procs = curvature.estimate(torus, "tc", fit="monge", tile_points=2000, executor=pool)
    assert_identical(curvature.estimate(torus, "tc", fit="monge", tile_points=0), procs)


def test_executor_progress_is_per_tile_and_complete(torus):
    seen = []
    curvature.estimate(torus, "knn", tile_points=1000, executor=RecordingExecutor(),
                       progress=lambda done, total: seen.append((done, total)))
    dones = [d for d, _ in seen]
    assert dones == sorted(dones) and dones[-1] == len(torus)
    assert {total for _, total in seen} == {len(torus)}
    assert len(set(dones) - {0}) == 8  # once per tile (and 0 while waiting for the first)


def test_a_failed_tile_fails_the_run_and_cancels_the_rest(torus, monkeypatch):
    monkeypatch.setattr(tiling, "IN_FLIGHT", 2)
    recorder = RecordingExecutor(fail_tile=0)
    with pytest.raises(RuntimeError, match="tile 0 failed"):
        curvature.estimate(torus, "knn", tile_points=1000, executor=recorder)
    assert len(recorder.submitted) < 8  # the window stopped further submissions
    recorder.pool.shutdown(wait=True)
    assert all(f.done() for f in recorder.futures)


def test_progress_raising_cancels_the_tiles_still_out(torus, monkeypatch):
    monkeypatch.setattr(tiling, "IN_FLIGHT", 2)

    class Stop(Exception):
        pass

    def progress(done, total):
        if done:
            raise Stop

    recorder = RecordingExecutor()
    with pytest.raises(Stop):
        curvature.estimate(torus, "knn", tile_points=1000, executor=recorder,
                           progress=progress)
    recorder.pool.shutdown(wait=True)
    assert len(recorder.submitted) <= 3  # the first tile back stopped the run


def test_executor_without_submit_is_a_parameter_error(torus):
    with pytest.raises(curvature.ParameterError, match="submit"):
        curvature.estimate(torus, executor=object())


@pytest.mark.parametrize("seed", range(4))
def test_a_tile_holds_every_point_within_each_core_points_room(seed):
    from scipy.spatial import cKDTree

    from curvature.pipeline.spatial_order import morton_order

    rng = np.random.default_rng(seed)
    blobs = [rng.normal(c, 0.3, (3000, 3)) for c in ((0, 0, 0), (5, 1, 0), (2, 6, 3))]
    pts = np.vstack(blobs)
    spts = np.ascontiguousarray(pts[morton_order(pts)])
    req = resolve_request(None, "knn", "monge", {"k": 12}, None, None, None, 1, 1000)
    halo = float(rng.uniform(0.05, 0.6))
    tiles = tiling.make_tiles(spts, 2500, halo)
    tree = cKDTree(spts)
    sizes = []
    for tile in tiles:
        inp = tiling.tile_input(spts, tile, req, None)
        members = set(inp.members.tolist())
        core = spts[tile.start:tile.stop]
        room = tiling.halo_room(core, tile)
        assert np.all(room >= halo * (1 - 1e-6))
        for i in rng.choice(len(core), 60, replace=False):
            near = tree.query_ball_point(core[i], room[i] * (1 - 1e-12))
            assert members.issuperset(near), (tile.index, i)
        sizes.append(len(members))
    # a Z-order run spanning two blobs keeps their surroundings, not the box between them
    box = [np.all((spts >= np.asarray(t.lo) - halo) & (spts <= np.asarray(t.hi) + halo),
                  axis=1).sum() for t in tiles]
    assert sum(sizes) <= sum(box)


def test_local_tiled_progress_moves_inside_tiles_and_never_back(torus, monkeypatch):
    monkeypatch.setattr(tiling, "AUTO_HALO", 0.5)  # short halos: some tiles run twice
    seen = []
    res = curvature.estimate(torus, tile_points=2000,
                             progress=lambda done, total: seen.append((done, total)))
    assert res.info["regrown"] > 0
    dones = [d for d, _ in seen]
    assert dones == sorted(dones) and dones[-1] == len(torus)
    assert len(set(dones)) > 2 * res.info["tiles"]  # more steps than tiles


def test_dense_tiles_share_one_stage1_and_hold_only_thinned_halos(monkeypatch):
    # Dense clouds: the thinned points' normals, outlier tests and the orientation graph are
    # made once for the whole cloud (TiledRun), and a tile's halo holds only the thinned
    # points, the only ones its fits read. Short halos (regrown tiles) and an executor too.
    from curvature.pipeline.spatial_order import morton_order

    pts = synthetic.sphere(40_000, noise=0.8, seed=3).points[:20_000]
    whole = curvature.estimate(pts, dense_noise=0.3, tile_points=0)
    assert whole.info["plan"]["dense"] is not None
    spts = np.ascontiguousarray(pts[morton_order(pts)])
    req = resolve_request(None, None, None, {"dense_noise": 0.3}, None, None, None, 1, 2000)
    run = tiling.TiledRun(spts, None, req, 5000)
    thin, field, r_normal, outlier, flat = run.dense_stage1
    share = run.plan.dense_share
    assert abs(thin.size / len(pts) - share) < 0.02 and np.all(np.diff(thin) > 0)
    assert field.shape == (thin.size, 3) and r_normal.shape == outlier.shape == thin.shape
    assert flat.shape == thin.shape
    for tile in run.tiles:
        inp = run.input(tile)
        own = (inp.members >= tile.start) & (inp.members < tile.stop)
        assert np.all(np.isin(inp.members[~own], thin)) and own.sum() == tile.stop - tile.start
        local = inp.dense_stage1[0]
        np.testing.assert_array_equal(inp.members[local], thin[np.isin(thin, inp.members)])
    tiled = curvature.estimate(pts, dense_noise=0.3, tile_points=5000)
    assert_identical(whole, tiled)
    monkeypatch.setattr(tiling, "AUTO_HALO", 0.5)
    short = curvature.estimate(pts, dense_noise=0.3, tile_points=5000,
                               executor=RecordingExecutor())
    assert short.info["regrown"] > 0
    assert_identical(whole, short)


def test_the_whole_cloud_stage1_of_a_dense_cloud_reports_and_can_be_cancelled():
    pts = synthetic.sphere(40_000, noise=0.8, seed=3).points[:20_000]
    calls = []

    def cancel(done, total):
        calls.append((done, total))
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        curvature.estimate(pts, dense_noise=0.3, tile_points=5000, progress=cancel)
    assert calls == [(0, len(pts))]  # before any tile ran
