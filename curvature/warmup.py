"""Compile every numba kernel the library uses into numba's on-disk cache.

``python -m curvature.warmup`` runs each method, fit, orientation, tiling and reader once on
tiny clouds, serially and with two threads (the threaded kernels are separate functions), so
every ``cache=True`` kernel is compiled for the argument types real runs give it and written to
``__pycache__`` next to its source. Later processes load the machine code from there in about a
second instead of compiling for minutes. With a valid cache the whole run takes seconds, so it
is safe to run at every install. When the sources changed since the last complete run, every
cached kernel is deleted first and compiled again (:func:`clear_stale_cache`): numba drops
only the entries of the file that changed, and a kernel in another file compiled against it
would keep the old code.

A successful run leaves ``__pycache__/kernels.warm`` holding a fingerprint of the package's
sources; :func:`cache_is_warm` compares it, so a caller (the service, the tests) can tell in
advance whether its first estimate loads kernels or compiles them.

Exit status 1 when a kernel was never compiled (a new kernel the steps below do not reach).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from collections.abc import Callable, Iterator
from importlib import import_module
from pathlib import Path
from pkgutil import walk_packages

import numpy as np

from . import synthetic
from .io import read_bytes, write_bytes
from .io.lzf import lzf_decompress
from .neighborhoods.kdtree import build_tree, knn_rows
from .pipeline import estimate

Step = tuple[str, Callable[[], object]]
PACKAGE = Path(__file__).resolve().parent
STAMP = PACKAGE / "__pycache__" / "kernels.warm"


def fingerprint() -> str:
    """Hash of every source file's path, size and modification time (what numba's cache
    index checks), and of the Python and numba versions."""
    import numba

    digest = hashlib.sha256(f"{sys.version} {numba.__version__}".encode())
    for path in sorted(PACKAGE.rglob("*.py")):
        stat = path.stat()
        digest.update(f"{path.relative_to(PACKAGE)} {stat.st_size} {stat.st_mtime_ns}\n"
                      .encode())
    return digest.hexdigest()


def cache_is_warm() -> bool:
    """True when the last complete warm-up ran on the sources as they are now."""
    try:
        return STAMP.read_text().strip() == fingerprint()
    except OSError:
        return False


def _sphere_mesh(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points on the unit sphere, shape (n, 3), and their convex hull's triangles (m, 3)."""
    from scipy.spatial import ConvexHull

    pts = synthetic.sphere(n, seed=3).points
    return pts, ConvexHull(pts).simplices.astype(np.int64)


def _mixed_faces_ply() -> bytes:
    """A binary PLY of a square pyramid, one quad and four triangles (list rows of two
    lengths), and the same five vertices again higher up (the reader wants ten points)."""
    apex = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], "<f4")
    verts = np.vstack([apex, apex + np.float32(2)])
    faces = [(0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)]
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 5\n"
              b"property list uchar int vertex_indices\nend_header\n")
    body = b"".join(bytes([len(f)]) + np.array(f, "<i4").tobytes() for f in faces)
    return header + verts.tobytes() + body


def _literal_lzf(raw: bytes) -> bytes:
    """``raw`` as an LZF stream of literal runs only (control byte ``c``: ``c + 1`` bytes)."""
    out = bytearray()
    for start in range(0, len(raw), 32):
        chunk = raw[start:start + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def _compressed_pcd(points: np.ndarray) -> bytes:
    """A binary_compressed PCD of ``points`` (n, 3) as float32, fields one after another."""
    n = points.shape[0]
    raw = np.ascontiguousarray(points.astype("<f4").T).tobytes()
    packed = _literal_lzf(raw)
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
              "DATA binary_compressed\n").encode()
    return header + np.array([len(packed), len(raw)], "<u4").tobytes() + packed


def _anchor_fits_once(cloud) -> None:
    """``nfr_anchor_fits`` on a few anchors: the default now fits every anchor through the
    scale selection (an empty ladder when ``scale_gamma`` is 0), the tests still call it."""
    from .fitting.normal_field import N_TERMS, nfr_anchor_fits
    from .fitting.normal_quadric import N_QUAD

    pts, k = cloud.points, 24
    anchors = np.arange(0, 200, 10, dtype=np.int64)
    a = anchors.shape[0]
    nbr = knn_rows(pts, build_tree(pts), anchors, k + 1)[0][:, 1:].astype(np.int32)
    nfr_anchor_fits(pts, cloud.normals, anchors, np.arange(0, (a + 1) * k, k, dtype=np.int64),
                    nbr.ravel(), 0.7, np.empty((a, 2, N_TERMS)), np.empty(a),
                    np.empty((a, 3, 3)), np.empty((a, N_QUAD)), np.empty(a),
                    np.empty(a, np.int8), np.empty(a), np.empty(a, np.int8))


def _flip_once() -> None:
    """``orientation._flip_subtree`` on a three-point forest: it runs only where the cut
    repair flips a subtree, which no cloud of the warm-up is sure to need."""
    from .orientation import _flip_subtree

    parent = np.array([-1, 0, 1], np.int32)
    _flip_subtree(parent, np.arange(3, dtype=np.int32), np.ones(3, np.int8), 1)


def steps() -> Iterator[Step]:
    """Every run the warm-up makes, as ``(label, call)``."""
    clean = synthetic.torus(1500, seed=1)
    noisy = synthetic.torus(1500, noise=1.0, seed=2)
    # relative wide noise about 0.46: thinned to a fifth with dense_noise=0.25
    dense = synthetic.torus(4000, noise=2.0, seed=3)
    # faces 3 spacings apart: stage 1 reads them over one side (estimators.wall_sides); fewer
    # points read the other face as noise and take the dense branch
    wall = synthetic.thin_plate(10000, noise=0.1, seed=1)
    for workers in (1, 2):
        def run(*args, _w=workers, **kw):
            return lambda: estimate(*args, workers=_w, **kw)

        threads = f"{workers} thread(s)"
        # the ring kernels run threaded from 4096 queries on
        mesh_pts, faces = _sphere_mesh(300 if workers == 1 else 4200)
        # a coarse torus: the threshold keeps the clean branch whatever its measured noise
        yield f"auto clean, {threads}", run(clean.points, noise_threshold=1.0)
        yield f"auto noisy, {threads}", run(noisy.points)
        yield f"auto noisy at one scale, {threads}", run(noisy.points, scale_gamma=0.0)
        yield f"auto dense, {threads}", run(dense.points, dense_noise=0.25)
        yield f"auto thin wall, {threads}", run(wall.points)
        for fit, extra in (("implicit", {}), ("implicit", {"solver": "algebraic"}),
                           ("monge", {}), ("adaptive", {}), ("nfr", {"k": 60})):
            yield (f"knn {fit} {extra or ''}, {threads}",
                   run(clean.points, "knn", fit=fit, **{"k": 24, **extra}))
        yield f"tc, {threads}", run(clean.points, "tc")
        yield f"egg, {threads}", run(clean.points, "egg")
        yield f"mesh, {threads}", run(mesh_pts, "mesh", faces=faces)
        yield f"mesh without faces, {threads}", run(clean.points, "mesh")
        yield f"orientation normals, {threads}", run(clean.points, "knn",
                                                      normals=clean.normals)
        yield f"orientation viewpoint, {threads}", run(clean.points, "knn",
                                                        viewpoint=[0.0, 0.0, 10.0])
        yield f"tiled, {threads}", run(clean.points, "knn", tile_points=1000)
    ply = write_bytes(clean.points, "ply")
    yield "read binary ply", lambda: read_bytes(ply, "ply")
    yield "read binary ply, faces of mixed sizes", lambda: read_bytes(_mixed_faces_ply(), "ply")
    yield "k-d tree, serial query", lambda: knn_rows(clean.points, build_tree(clean.points),
                                                     np.arange(10, dtype=np.int64), 5)
    yield "read compressed pcd", lambda: read_bytes(_compressed_pcd(clean.points[:100]), "pcd")
    yield "lzf", lambda: lzf_decompress(_literal_lzf(b"warm-up"), 7)
    yield "anchored fits without scale selection", lambda: _anchor_fits_once(noisy)
    yield "orientation, a subtree flipped", _flip_once


def kernels() -> Iterator[tuple[str, object]]:
    """Every numba dispatcher defined in the package, as ``("module.name", dispatcher)``.

    Kernels marked ``inline="always"`` are left out: numba inlines them into their callers
    and never compiles them on their own.
    """
    from numba.core.registry import CPUDispatcher

    for info in walk_packages([str(PACKAGE)], prefix=f"{__package__}."):
        if info.name.endswith((".__main__", ".warmup")):
            continue
        module = import_module(info.name)
        for name, obj in vars(module).items():
            if (isinstance(obj, CPUDispatcher) and obj.__module__ == module.__name__
                    and obj.targetoptions.get("inline") != "always"):
                yield f"{module.__name__}.{name}", obj


def _callees(kernel) -> list:
    """The kernels that ``kernel`` calls by a global name."""
    from numba.core.registry import CPUDispatcher

    space = kernel.py_func.__globals__
    return [space[name] for name in kernel.py_func.__code__.co_names
            if isinstance(space.get(name), CPUDispatcher)]


def uncompiled() -> list[str]:
    """Names of the package's kernels that no compiled (or cache-loaded) kernel covers.

    A kernel loaded from the cache carries the machine code of the kernels it calls, which
    then show no compiled version of their own; they count as covered through their caller.
    With a single numba thread the threaded kernels are never called, so they do not count.
    """
    import numba

    found = dict(kernels())
    covered: set[int] = set()
    todo = [kernel for kernel in found.values() if kernel.signatures]
    while todo:
        kernel = todo.pop()
        if id(kernel) not in covered:
            covered.add(id(kernel))
            todo.extend(_callees(kernel))
    threaded = numba.config.NUMBA_NUM_THREADS > 1
    return sorted(name for name, kernel in found.items() if id(kernel) not in covered
                  and (threaded or not kernel.targetoptions.get("parallel")))


def clear_stale_cache() -> int:
    """Delete every numba cache file of the package when the sources changed since the last
    complete warm-up (a stamp that no longer matches); returns how many.

    Numba checks only the source file of each cached kernel: a kernel whose file did not
    change keeps the machine code compiled against the old version of a kernel it calls from
    another file (measured here: after a change to ``nfr_anchor_fits_one`` in
    ``fitting/normal_field.py`` the scale selection in ``fitting/scale_selection.py`` kept
    running the old one until its cache was deleted). Without a stamp (a fresh install)
    nothing is deleted.
    """
    if not STAMP.exists() or cache_is_warm():
        return 0
    count = 0
    for pattern in ("*.nbi", "*.nbc"):
        for path in PACKAGE.rglob(pattern):
            try:
                path.unlink()
                count += 1
            except OSError:  # already gone (another process cleared it) or read-only
                pass
    return count


def run(report: Callable[[str], None] = print) -> list[str]:
    """Run every step, reporting progress; returns :func:`uncompiled` afterwards. A cache
    left by other sources is deleted first (:func:`clear_stale_cache`).

    Parameters
    ----------
    report : callable
        Called with one line of progress per step (step number, label, seconds).
    """
    started = time.perf_counter()
    cleared = clear_stale_cache()
    todo = list(steps())
    for i, (label, call) in enumerate(todo, 1):
        t0 = time.perf_counter()
        call()
        report(f"kernels {i}/{len(todo)}: {label} ({time.perf_counter() - t0:.1f} s)")
    missing = uncompiled()
    if not missing:
        try:
            STAMP.write_text(fingerprint() + "\n")
        except OSError as exc:  # a read-only install still works, it just cannot tell
            report(f"cannot record the warm cache in {STAMP}: {exc}")
    report(f"kernels ready in {time.perf_counter() - started:.1f} s"
           + (f" ({cleared} stale cached kernel files deleted first)" if cleared else "")
           + (f"; never compiled: {', '.join(missing)}" if missing else ""))
    return missing


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m curvature.warmup", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-q", "--quiet", action="store_true", help="print the last line only")
    args = parser.parse_args(argv)
    lines: list[str] = []
    missing = run(lines.append if args.quiet else lambda line: print(line, flush=True))
    if args.quiet:
        print(lines[-1])
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
