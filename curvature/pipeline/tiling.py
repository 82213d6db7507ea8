"""Spatial tiles with verified halos: a big cloud computed piece by piece, bit for bit.

The Z-ordered cloud is cut into tiles of consecutive points (``tile_points`` each), which are
compact in space. A tile is computed together with its *halo*: every point within distance
``h`` of the tile's bounding box. Each computation reports, per point, its *reach*: a distance
within which lies every point its result depends on (its neighbors, the points a neighborhood
method examined, the neighbors behind the stage-1 normals, the anchors of the default
estimator and their neighborhoods). When a point's reach is shorter than its distance to the
outside of the halo, the tile holds everything the whole cloud would give it, in the same
relative order (tiles keep the cloud's Z-order, and every neighbor search breaks ties by that
order), so its result is identical bit for bit. Otherwise the halo grows and the tile is
computed again; a halo that covers the whole cloud is exact by definition, so this ends.

What a tile cannot see from inside is measured on the whole cloud first and handed to every
tile: the default estimator's plan (spacing, noise, anchor grid) and, for method "mesh", the
vertex graph (from the faces or from local Delaunay triangulations), whose edges can join
points far apart.

Tiles are the unit of work for distributed runs: :func:`tile_input` gives a self-contained,
picklable description of one tile, :func:`compute_tile` computes it anywhere, and
:class:`TiledRun` checks and assembles the answers.
"""

from __future__ import annotations

import math
import queue
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from ..bounds import bounding_box, diagonal, inside_box
from ..estimators.auto import (
    knn_csr,
    largest_fit,
    neighbor_rows,
    plan_auto,
    plan_sample,
    whole_dense_stage1,
)
from ..neighborhoods import make_finder
from ..neighborhoods.kdtree import build_tree
from ..orientation import ORIENT_K
from .block import DERIVED, compute_block, empty_result
from .request import Request
from .threads import numba_threads

# Halo guesses in spacings (distance to the 24th neighbor); a wrong guess costs a recomputation,
# never a wrong result.
# The default's first halo, in radii of its largest fit: the median distance to the k-th
# neighbor on the plan's sample, over sqrt(dense_share) where the fits see a thinned share
# (k thinned points cover k / share). Its second pass reads normals the first pass fitted over
# as many neighbors, refined again by a pass as wide away from features: the largest reach
# measured was 7.0 radii (1M-point torus, 0.1 % noise), 6.3 at 100k points, 5.9 and 6.2 at 1M
# and 3M points thinned to 0.10 and 0.13 (4.2 to 4.5 before the second refinement, with a
# halo of 5.5). A halo of 16 spacings made every tile of those run twice; one in spacings (the
# 24th neighbor) is too wide on dense noisy clouds, whose spacing the noise inflates (1.9
# times at 10M points).
AUTO_HALO = 8.5
HALO_MARGIN = 1.5
GROWTH = 1.5
# Tiles handed to an executor at once: keeps every worker busy while bounding the memory of
# tile inputs waiting to be sent.
IN_FLIGHT = 8
# Seconds between progress calls while waiting for tiles (they are also the cancellation check).
WAIT_POLL = 0.5


@dataclass(frozen=True)
class Tile:
    """One tile: points ``start:stop`` of the Z-ordered cloud, their box and halo width."""

    index: int
    start: int
    stop: int
    lo: tuple
    hi: tuple
    halo: float


@dataclass
class TileInput:
    """Everything needed to compute one tile, picklable (sent to workers as is).

    Attributes
    ----------
    tile : Tile
    points : ndarray, shape (m, 3)
        The tile's points and its halo, in the cloud's order.
    members : ndarray, shape (m,), int64
        Their indices in the Z-ordered cloud (increasing).
    query : ndarray, shape (c,), int64
        Indices into ``points`` of the tile's own points.
    request : Request
    plan : AutoPlan
    mesh_graph : tuple of ndarray or None
        The cloud's vertex graph restricted to ``members`` (method "mesh").
    dense_stage1 : tuple of ndarray or None
        The whole cloud's :func:`~curvature.estimators.auto.dense_stage1` at the thinned
        ``members`` (indices into ``points``; method "auto" on a dense cloud).
    """

    tile: Tile
    points: np.ndarray
    members: np.ndarray
    query: np.ndarray
    request: Request
    plan: object
    mesh_graph: tuple | None = None
    dense_stage1: tuple | None = None


@dataclass
class TileOutput:
    """A computed tile: result rows of its own points, graph rows in cloud indices, and
    whether the halo held every point's reach (``short``: how many did not); ``own_std``
    (its points, bool, or None) as :class:`~curvature.pipeline.block.Block`'s."""

    tile: Tile
    fields: dict
    graph: np.ndarray | None
    short: int
    needed: float
    info: dict
    seconds: float
    own_std: np.ndarray | None = None


def halo_guess(req: Request, spacing: float, fit_radius: float = math.nan) -> float:
    """A first halo width for ``req`` on a cloud of the given spacing; for the default,
    ``fit_radius`` is the median distance to the ``k``-th neighbor (:func:`fit_radius`)."""
    def size(k):
        return math.sqrt(max(k, 1) / 24.0) * spacing

    p = req.method_params
    if req.method == "auto":
        if not fit_radius > 0.0:  # not measured: the fit's radius on a flat, even cloud
            fit_radius = size(req.auto_params.get("k", 768))
        return AUTO_HALO * fit_radius
    if req.method == "knn":
        reach = size(p.get("k", 24))
    elif req.method == "tc":
        reach = size(p.get("candidates", 30) + p.get("min_neighbors", 10))
    elif req.method == "egg":
        reach = size(p.get("candidates", 30))
    else:  # mesh: a few rings
        reach = 3.0 * spacing
    if req.fit == "nfr":
        reach += size(req.fit_opts.get("normal_k", 48))
    return HALO_MARGIN * reach


def fit_radius(spts: np.ndarray, tree: tuple, k: int, sample: np.ndarray | None = None) -> float:
    """Median distance to the ``k``-th neighbor over the plan's geometric sample
    (:func:`~curvature.estimators.auto.plan_sample`, computed if not given)."""
    if sample is None:
        sample = plan_sample(spts)
    k = min(k, spts.shape[0] - 1)
    _, _, d2 = knn_csr(spts, tree, sample, k)
    return float(np.median(np.sqrt(d2[:, -1])))


def make_tiles(spts: np.ndarray, tile_points: int, halo: float) -> list[Tile]:
    """Consecutive runs of ``tile_points`` Z-ordered points, with their bounding boxes."""
    n = spts.shape[0]
    tiles = []
    for i, start in enumerate(range(0, n, tile_points)):
        stop = min(start + tile_points, n)
        core = spts[start:stop]
        lo, hi = bounding_box(core)
        tiles.append(Tile(i, start, stop, tuple(lo), tuple(hi), halo))
    return tiles


def restrict_graph(graph: tuple, members: np.ndarray, n: int) -> tuple:
    """A CSR vertex graph restricted to ``members`` (edges with both ends kept), renumbered."""
    indptr, indices = graph
    local = np.full(n, -1, np.int64)
    local[members] = np.arange(members.shape[0])
    deg = indptr[members + 1] - indptr[members]
    rows = np.repeat(np.arange(members.shape[0]), deg)
    starts = np.repeat(indptr[members] - np.cumsum(np.r_[0, deg[:-1]]), deg)
    cols = local[indices[np.arange(rows.shape[0]) + starts]]
    keep = cols >= 0
    rows, cols = rows[keep], cols[keep]
    out_ptr = np.zeros(members.shape[0] + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=members.shape[0]), out=out_ptr[1:])
    return out_ptr, cols.astype(np.int64)


@njit(parallel=True, cache=True)
def _cell_keys(points, rows, origin, size):
    """One int64 per point ``points[rows]`` naming its cube of side ``size`` (21 bits per
    axis), shape (len(rows),)."""
    keys = np.empty(rows.shape[0], np.int64)
    for t in prange(rows.shape[0]):
        key = 0
        for a in range(3):  # (+ 1: >= 0 past the dilation)
            key = (key << 21) | (int(np.floor((points[rows[t], a] - origin[a]) / size)) + 1)
        keys[t] = key
    return keys


_OFFSETS = np.array([(dx << 42) + (dy << 21) + dz for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                     for dz in (-1, 0, 1)], np.int64)


def _halo_box(tile: Tile) -> tuple[np.ndarray, np.ndarray, bool]:
    """Corners of the tile's box grown by its halo, and whether the cube filter applies
    (a finite halo whose cubes' keys fit their 21 bits)."""
    lo = np.asarray(tile.lo) - tile.halo
    hi = np.asarray(tile.hi) + tile.halo
    cubes = math.isfinite(tile.halo) and tile.halo > 0 \
        and bool(np.all((hi - lo) / tile.halo < (1 << 20)))
    return lo, hi, cubes


def tile_input(spts: np.ndarray, tile: Tile, req: Request, plan, mesh_graph=None,
               dense_stage1=None) -> TileInput:
    """The points of ``tile`` plus its halo, ready for :func:`compute_tile`.

    The halo is every point within ``tile.halo`` of the tile's box that also lies in a cube
    of side ``tile.halo`` next to a cube holding a tile point: a Z-order run can span two
    separate regions, whose common box would hold far more than their surroundings.
    With ``dense_stage1``, the whole cloud's (cloud indices), the halo holds only the points
    it was made for (the thinned points: nothing else of the halo is read), and it is
    restricted to the members.
    """
    lo, hi, cubes = _halo_box(tile)
    inside = inside_box(spts, lo, hi)
    inside[tile.start:tile.stop] = True
    members = np.flatnonzero(inside).astype(np.int64)
    del inside
    if dense_stage1 is not None:
        own = (members >= tile.start) & (members < tile.stop)
        thinned = dense_stage1[0]
        if thinned.shape[0]:
            at = np.minimum(np.searchsorted(thinned, members), thinned.shape[0] - 1)
            own |= thinned[at] == members
            del at
        members = members[own]
        del own
    if cubes:
        core = _cell_keys(spts, np.arange(tile.start, tile.stop, dtype=np.int64), lo,
                          tile.halo)
        near = np.unique((np.unique(core)[:, None] + _OFFSETS[None, :]).ravel())
        # (near is sorted and unique: a binary search per point, no sort of the members)
        keys = _cell_keys(spts, members, lo, tile.halo)
        at = np.minimum(np.searchsorted(near, keys), near.shape[0] - 1)
        keep = near[at] == keys
        del keys, at
        keep[(members >= tile.start) & (members < tile.stop)] = True
        members = members[keep]
    offset = int(np.searchsorted(members, tile.start))
    query = np.arange(offset, offset + tile.stop - tile.start, dtype=np.int64)
    graph = None if mesh_graph is None else restrict_graph(mesh_graph, members, spts.shape[0])
    if dense_stage1 is not None:
        dense_stage1 = restrict_rows(dense_stage1, members)
    return TileInput(tile, np.ascontiguousarray(spts[members]), members, query, req, plan,
                     graph, dense_stage1)


def restrict_rows(rows: tuple, members: np.ndarray) -> tuple:
    """Per-point arrays ``(index, *values)`` of some points of the cloud (index increasing)
    restricted to ``members`` (increasing), their index renumbered into ``members``."""
    index = rows[0]
    at = np.minimum(np.searchsorted(members, index), members.shape[0] - 1)
    keep = np.flatnonzero(members[at] == index)
    return (at[keep], *(values[keep] for values in rows[1:]))


def halo_room(core: np.ndarray, tile: Tile) -> np.ndarray:
    """How far around each tile point the tile holds every point of the cloud, shape (c,).

    The box grown by the halo holds everything within its faces' distance; the cube filter
    of :func:`tile_input` keeps the 27 cubes around the point's own, so everything within the
    halo plus the distance to its own cube's faces.
    """
    lo, hi, cubes = _halo_box(tile)
    box = np.minimum((core - lo).min(axis=1), (hi - core).min(axis=1))
    if not cubes:
        return box
    frac = (core - lo) / tile.halo
    inner = np.minimum(frac - np.floor(frac), np.ceil(frac) - frac).min(axis=1)
    # (a hair less: a point on a cube face may round into the next cube)
    return np.minimum(box, tile.halo * (1.0 + inner) * (1.0 - 1e-9))


def compute_tile(inp: TileInput, progress=None) -> TileOutput:
    """Compute one tile and check its halo (runs anywhere: a thread, a process, a cluster).

    ``progress(fraction)``, if given, follows the tile's own work (local runs).
    """
    t0 = time.perf_counter()
    step = None if progress is None else (lambda done, total: progress(done / max(total, 1)))
    with numba_threads(inp.request.workers):
        block = compute_block(inp.points, None, inp.request, inp.query, progress=step,
                              plan=inp.plan, mesh_graph=inp.mesh_graph, track_reach=True,
                              dense_stage1=inp.dense_stage1)
    room = halo_room(inp.points[inp.query], inp.tile)
    whole = inp.tile.halo == math.inf  # every point of the cloud is in the tile
    # a point must see strictly past its reach (NaN reach counts as short)
    short = ~(block.reach < room) & ~whole
    graph = None
    if block.graph is not None:
        graph = np.where(block.graph >= 0, inp.members[np.maximum(block.graph, 0)], -1)
        graph = graph.astype(np.int32)
    # mean and Gaussian curvature are derived after assembly: not sent back
    fields = {k: v for k, v in block.result.fields().items() if k not in DERIVED}
    return TileOutput(inp.tile, fields, graph, int(short.sum()),
                      float(np.nanmax(block.reach)) if block.reach.size else 0.0, block.info,
                      time.perf_counter() - t0, block.own_std)


def grown(tile: Tile, out: TileOutput, extent: float) -> Tile:
    """The tile with a wider halo after ``out`` came back short (infinite past the cloud)."""
    halo = max(tile.halo * GROWTH, out.needed * 1.05)
    if halo >= extent:
        halo = math.inf
    return Tile(tile.index, tile.start, tile.stop, tile.lo, tile.hi, halo)


@dataclass
class TiledRun:
    """A cloud computed tile by tile: the shared measurements, the tiles and the assembly.

    Parameters
    ----------
    spts : ndarray, shape (n, 3)
        The Z-ordered cloud.
    s_faces : ndarray, shape (f, 3), optional
        Faces in Z-order indices (method "mesh").
    req : Request
    tile_points : int
    progress : callable, optional
        ``progress(0, n)`` is called while the whole cloud's stage-1 work runs (dense
        clouds, before any tile): it may raise to cancel.
    """

    spts: np.ndarray
    s_faces: np.ndarray | None
    req: Request
    tile_points: int
    plan: object = None
    mesh_graph: tuple | None = None
    tiles: list = field(default_factory=list)
    regrown: int = 0
    progress: object = None

    def __post_init__(self):
        n = self.spts.shape[0]
        tree = build_tree(self.spts)
        threshold = self.req.auto_params.get("noise_threshold", 0.01)
        sample = plan_sample(self.spts)
        self.plan = plan_auto(self.spts, tree, threshold,
                              self.req.auto_params.get("dense_noise", math.inf), sample)
        if self.req.method == "mesh":
            finder = make_finder(self.spts, "mesh", faces=self.s_faces, **self.req.method_params)
            finder._nbtree = tree
            self.mesh_graph = finder.graph(self.req.workers)
        radius = math.nan
        if self.req.method == "auto":
            radius = (fit_radius(self.spts, tree, largest_fit(self.req.auto_params, self.plan),
                                 sample)
                      / math.sqrt(self.plan.dense_share))
        self.graph = np.empty((n, ORIENT_K), np.int32) if self.req.mode == "auto" else None
        self.dense_stage1 = None
        if self.req.method == "auto" and self.plan.dense is not None:
            # Once for the whole cloud: every tile would compute it again for its halo,
            # which holds 2 to 3 times the tile's points (10M-point torus, tiles of 1M).
            # Its tiles then need no other halo point, and so no tree of their own for
            # the orientation graph: that is made here too.
            # (no point is done yet, but a progress call may cancel the run)
            tick = None if self.progress is None else (lambda count: self.progress(0, n))
            self.dense_stage1 = whole_dense_stage1(self.spts, tree, self.plan,
                                                   self.req.auto_params,
                                                   self.req.chunk_size, tick)
            if self.graph is not None:
                neighbor_rows(self.spts, tree, self.graph, self.req.chunk_size, tick=tick)
        del tree
        self.extent = diagonal(self.spts)
        self.tiles = make_tiles(self.spts, self.tile_points,
                                halo_guess(self.req, self.plan.spacing, radius))
        self.result = empty_result(self.spts, self.s_faces)
        self.own_std = np.zeros(n, bool)
        self.info: dict = {}
        self.seconds = 0.0
        self.done = 0

    def input(self, tile: Tile) -> TileInput:
        return tile_input(self.spts, tile, self.req, self.plan, self.mesh_graph,
                          self.dense_stage1)

    def accept(self, out: TileOutput) -> Tile | None:
        """Store a tile's rows, or return the tile with a wider halo to compute again."""
        if out.short:
            self.regrown += 1
            return grown(out.tile, out, self.extent)
        sl = slice(out.tile.start, out.tile.stop)
        for name, arr in out.fields.items():
            if name not in DERIVED:
                getattr(self.result, name)[sl] = arr
        if out.graph is not None:  # (dense clouds: made for the whole cloud)
            self.graph[sl] = out.graph
        if out.own_std is not None:
            self.own_std[sl] = out.own_std
        self.tiles[out.tile.index] = out.tile
        self.info = out.info
        self.seconds += out.seconds
        self.done += out.tile.stop - out.tile.start
        return None

    def summary(self) -> dict:
        halos = [t.halo for t in self.tiles]
        return {**self.info, "tiles": len(self.tiles), "tile_points": self.tile_points,
                "halo_max": max(halos), "regrown": self.regrown}


def run_tiled(spts, s_faces, req: Request, tile_points: int, progress=None, executor=None):
    """Compute a Z-ordered cloud tile by tile, in this process or on ``executor``.

    Returns
    -------
    result : CurvatureResult
        Unoriented, Z-ordered.
    graph : ndarray or None
        Orientation graph (n, ORIENT_K) in Z-order indices.
    info, timings : dict
    own_std : ndarray, shape (n,), bool
        The points whose standard errors are their own fit's
        (:class:`~curvature.pipeline.block.Block`).
    """
    t0 = time.perf_counter()
    run = TiledRun(spts, s_faces, req, tile_points, progress=progress)
    t_plan = time.perf_counter() - t0
    n = spts.shape[0]
    if executor is None:
        shown = [0]  # never backwards, even when a tile is computed again

        def report(done):
            shown[0] = max(shown[0], done)
            progress(shown[0], n)

        for tile in list(run.tiles):
            inside = None
            if progress is not None:  # the bar moves inside each tile too
                size = tile.stop - tile.start

                def inside(fraction, size=size):
                    report(min(run.done + int(fraction * size), n - 1))

            while tile is not None:
                tile = run.accept(compute_tile(run.input(tile), inside))
            if progress is not None:
                report(run.done)
    else:
        run_on(executor, run, progress)
    timings = {"plan": t_plan, "tiles": run.seconds, "wall": time.perf_counter() - t0 - t_plan}
    return run.result, run.graph, run.summary(), timings, run.own_std


def run_on(executor, run: TiledRun, progress=None, in_flight: int | None = None) -> None:
    """Compute every tile of ``run`` on ``executor``, at most ``in_flight`` at a time.

    Tiles are accepted in the order they finish; a short halo sends its tile back with a wider
    one. Any exception (a failed tile, or one raised by ``progress`` to cancel) cancels the
    tiles still out and propagates. A tile lost with a worker is the executor's to recompute
    (Dask does so by itself).
    """
    n = run.spts.shape[0]
    in_flight = in_flight or IN_FLIGHT
    finished: queue.SimpleQueue = queue.SimpleQueue()
    todo = deque(run.tiles)
    out: dict[int, object] = {}  # id(future) -> future
    try:
        while todo or out:
            while todo and len(out) < in_flight:
                future = executor.submit(compute_tile, run.input(todo.popleft()))
                out[id(future)] = future
                future.add_done_callback(finished.put)
            try:
                future = finished.get(timeout=WAIT_POLL)
            except queue.Empty:
                if progress is not None:
                    progress(run.done, n)
                continue
            out.pop(id(future), None)
            again = run.accept(future.result())
            if again is not None:
                todo.appendleft(again)
            elif progress is not None:
                progress(run.done, n)
    except BaseException:
        for future in out.values():
            future.cancel()
        raise


__all__ = ["Tile", "TileInput", "TileOutput", "TiledRun", "compute_tile", "make_tiles",
           "run_on", "run_tiled", "tile_input"]
