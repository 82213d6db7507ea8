"""Tiles of a job as tasks on a Dask distributed cluster (executor "dask").

Runs inside the pool's worker processes: each keeps one ``distributed.Client`` per scheduler
address and hands it to ``curvature.estimate`` as its tile executor. The library does the rest
(tiles with verified halos, at most a few in flight, progress per tile, cancelling the tiles
still out when the progress callback aborts). Tile tasks carry their own input, so the
scheduler can recompute a tile whose worker died; ``distributed`` is imported only here.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import warnings

from .problem_types import ProblemError

_clients: dict[str, object] = {}


class DaskTiles:
    """The ``submit(fn, arg)`` the library expects, as impure tasks on ``client``."""

    def __init__(self, client):
        self.client = client

    def submit(self, fn, arg):
        # Impure: a tile computed again after a lost worker must not reuse a cached key. The
        # tile's points travel inside the task on purpose (a task that carries its input can
        # be recomputed anywhere), so distributed's advice to scatter large data does not apply.
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Sending large graph")
            return self.client.submit(fn, arg, pure=False)


def client_for(address: str, timeout: float):
    """This process's client of the scheduler at ``address`` (connected on first use).

    Raises
    ------
    ProblemError
        ``cluster-unavailable`` when the scheduler cannot be reached within ``timeout``.
    """
    from distributed import Client

    client = _clients.get(address)
    if client is not None and client.status == "running":
        return client
    try:
        client = Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ProblemError("cluster-unavailable", f"could not reach the Dask scheduler at "
                           f"{address} within {timeout:g} s ({exc})") from None
    _clients[address] = client
    return client


def tile_options(options: dict) -> dict:
    """Extra ``curvature.estimate`` arguments of a run: ``executor`` and ``tile_points``.

    Empty unless the run's options name a Dask scheduler (``dask_address``).
    """
    address = options.get("dask_address")
    if not address:
        return {}
    client = client_for(address, options.get("dask_connect_seconds", 20.0))
    return {"executor": DaskTiles(client), "tile_points": options["dask_tile_points"]}


def cluster_problem(exc: BaseException) -> ProblemError | None:
    """The problem of an exception that came from the cluster rather than the computation."""
    try:
        from distributed import KilledWorker
        from distributed.comm.core import CommClosedError
    except ImportError:  # no cluster in use
        return None
    if isinstance(exc, KilledWorker):
        return ProblemError("cluster-unavailable", "a tile killed Dask workers more often than "
                            "the scheduler retries it (the tile may need more memory than a "
                            "worker has)")
    if isinstance(exc, CommClosedError | OSError | concurrent.futures.CancelledError
                  | asyncio.CancelledError):
        return ProblemError("cluster-unavailable", f"the Dask cluster failed during the run "
                            f"({type(exc).__name__}: {exc})")
    return None


def cluster_workers(address: str, timeout: float) -> int:
    """Number of workers of the cluster at ``address`` (connects a short-lived client)."""
    from distributed import Client

    with Client(address, timeout=timeout, set_as_default=False) as client:
        return len(client.scheduler_info().get("workers", {}))
