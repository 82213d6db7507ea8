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
import time
from dataclasses import dataclass, field

import numpy as np

from .auto import plan_auto
from .neighborhoods import make_finder
from .neighborhoods.kdtree import build_tree
from .orientation import ORIENT_K
from .pipeline import Request, compute_block, empty_result

# Halo guesses in spacings (distance to the 24th neighbor); a wrong guess costs a recomputation,
# never a wrong result.
AUTO_HALO = 16.0
HALO_MARGIN = 1.5
GROWTH = 1.5


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
    """

    tile: Tile
    points: np.ndarray
    members: np.ndarray
    query: np.ndarray
    request: Request
    plan: object
    mesh_graph: tuple | None = None


@dataclass
class TileOutput:
    """A computed tile: result rows of its own points, graph rows in cloud indices, and
    whether the halo held every point's reach (``short``: how many did not)."""

    tile: Tile
    fields: dict
    graph: np.ndarray | None
    short: int
    needed: float
    info: dict
    seconds: float
    members: int = 0


def halo_guess(req: Request, spacing: float) -> float:
    """A first halo width for ``req`` on a cloud of the given spacing."""
    def size(k):
        return math.sqrt(max(k, 1) / 24.0) * spacing

    p = req.method_params
    if req.method == "auto":
        return AUTO_HALO * spacing
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


def make_tiles(spts: np.ndarray, tile_points: int, halo: float) -> list[Tile]:
    """Consecutive runs of ``tile_points`` Z-ordered points, with their bounding boxes."""
    n = spts.shape[0]
    tiles = []
    for i, start in enumerate(range(0, n, tile_points)):
        stop = min(start + tile_points, n)
        core = spts[start:stop]
        tiles.append(Tile(i, start, stop, tuple(core.min(axis=0)), tuple(core.max(axis=0)),
                          halo))
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


def tile_input(spts: np.ndarray, tile: Tile, req: Request, plan, mesh_graph=None) -> TileInput:
    """The points of ``tile`` plus its halo, ready for :func:`compute_tile`."""
    lo = np.asarray(tile.lo) - tile.halo
    hi = np.asarray(tile.hi) + tile.halo
    inside = np.all((spts >= lo) & (spts <= hi), axis=1)
    inside[tile.start:tile.stop] = True
    members = np.flatnonzero(inside).astype(np.int64)
    offset = int(np.searchsorted(members, tile.start))
    query = np.arange(offset, offset + tile.stop - tile.start, dtype=np.int64)
    graph = None if mesh_graph is None else restrict_graph(mesh_graph, members, spts.shape[0])
    return TileInput(tile, np.ascontiguousarray(spts[members]), members, query, req, plan,
                     graph)


def compute_tile(inp: TileInput) -> TileOutput:
    """Compute one tile and check its halo (runs anywhere: a thread, a process, a cluster)."""
    t0 = time.perf_counter()
    block = compute_block(inp.points, None, inp.request, inp.query, plan=inp.plan,
                          mesh_graph=inp.mesh_graph, track_reach=True)
    core = inp.points[inp.query]
    lo = np.asarray(inp.tile.lo) - inp.tile.halo
    hi = np.asarray(inp.tile.hi) + inp.tile.halo
    room = np.minimum((core - lo).min(axis=1), (hi - core).min(axis=1))
    whole = inp.tile.halo == math.inf  # every point of the cloud is in the tile
    # a point must see strictly past its reach (NaN reach counts as short)
    short = ~(block.reach < room) & ~whole
    graph = None
    if block.graph is not None:
        graph = np.where(block.graph >= 0, inp.members[np.maximum(block.graph, 0)], -1)
        graph = graph.astype(np.int32)
    fields = block.result.fields()
    return TileOutput(inp.tile, fields, graph, int(short.sum()),
                      float(np.nanmax(block.reach)) if block.reach.size else 0.0, block.info,
                      time.perf_counter() - t0, int(inp.members.shape[0]))


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
    """

    spts: np.ndarray
    s_faces: np.ndarray | None
    req: Request
    tile_points: int
    plan: object = None
    mesh_graph: tuple | None = None
    tiles: list = field(default_factory=list)
    regrown: int = 0

    def __post_init__(self):
        n = self.spts.shape[0]
        tree = build_tree(self.spts)
        threshold = self.req.auto_params.get("noise_threshold", 0.01)
        self.plan = plan_auto(self.spts, tree, threshold)
        if self.req.method == "mesh":
            finder = make_finder(self.spts, "mesh", faces=self.s_faces, **self.req.method_params)
            finder._nbtree = tree
            self.mesh_graph = finder.graph(self.req.workers)
        del tree
        self.extent = float(np.linalg.norm(self.spts.max(axis=0) - self.spts.min(axis=0)))
        self.tiles = make_tiles(self.spts, self.tile_points,
                                halo_guess(self.req, self.plan.spacing))
        self.result = empty_result(self.spts, self.s_faces)
        self.graph = np.empty((n, ORIENT_K), np.int32) if self.req.mode == "auto" else None
        self.info: dict = {}
        self.seconds = 0.0
        self.done = 0

    def input(self, tile: Tile) -> TileInput:
        return tile_input(self.spts, tile, self.req, self.plan, self.mesh_graph)

    def accept(self, out: TileOutput) -> Tile | None:
        """Store a tile's rows, or return the tile with a wider halo to compute again."""
        if out.short:
            self.regrown += 1
            return grown(out.tile, out, self.extent)
        sl = slice(out.tile.start, out.tile.stop)
        for name, arr in out.fields.items():
            getattr(self.result, name)[sl] = arr
        if self.graph is not None:
            self.graph[sl] = out.graph
        self.tiles[out.tile.index] = out.tile
        self.info = out.info
        self.seconds += out.seconds
        self.done += out.tile.stop - out.tile.start
        return None

    def summary(self) -> dict:
        halos = [t.halo for t in self.tiles]
        return {**self.info, "tiles": len(self.tiles), "tile_points": self.tile_points,
                "halo_max": max(halos), "regrown": self.regrown}


def run_tiled(spts, s_faces, req: Request, tile_points: int, progress=None):
    """Compute a Z-ordered cloud tile by tile in this process.

    Returns
    -------
    result : CurvatureResult
        Unoriented, Z-ordered.
    graph : ndarray or None
        Orientation graph (n, ORIENT_K) in Z-order indices.
    info, timings : dict
    """
    t0 = time.perf_counter()
    run = TiledRun(spts, s_faces, req, tile_points)
    t_plan = time.perf_counter() - t0
    for tile in list(run.tiles):
        while tile is not None:
            tile = run.accept(compute_tile(run.input(tile)))
        if progress is not None:
            progress(run.done, spts.shape[0])
    timings = {"plan": t_plan, "tiles": run.seconds}
    return run.result, run.graph, run.summary(), timings


__all__ = ["Tile", "TileInput", "TileOutput", "TiledRun", "compute_tile", "make_tiles",
           "run_tiled", "tile_input"]
