"""CGAL's jet fitting as a benchmark reference (optional, needs CGAL's headers and a C++ compiler).

``CGAL::Monge_via_jet_fitting`` (Cazals and Pouget, CAGD 2005) fits a bivariate polynomial
("jet") of degree ``d`` to a point's neighbors, expressed as a height over their PCA plane, then
reads the Monge form of degree 2 off it: the normal, the principal directions and the principal
curvatures. The C++ driver ``benchmarks/cgal/jet_fitting.cpp`` (in the repository checkout, not
in the wheel) runs it for every point over its ``k`` nearest points, the point itself included,
from CGAL's kd-tree, on ``workers`` threads. :func:`build_cgal_jet` compiles it once into a cache
folder; :func:`cgal_jet_curvature` runs it. CGAL is header-only; on Debian it is the package
``libcgal-dev`` (which pulls in Boost, GMP and MPFR) plus ``libeigen3-dev`` for the solver.

How CGAL's output maps to our convention
----------------------------------------
CGAL's Monge normal comes out of the fit with an arbitrary sign, and its curvatures are those of
the height function ``z = (k1 x^2 + k2 y^2) / 2 + ...`` along that normal: positive where the
surface bends *towards* the normal. A sphere of radius r whose Monge normal happens to point
outward gives ``k1 = k2 = -1/r`` (checked in the tests). Ours is the opposite (positive where
the surface bends away from the oriented normal, ``+1/r`` on that sphere), so:

* where the Monge normal agrees with the given normal (positive dot product), our
  ``k1, k2 = -k2_cgal, -k1_cgal`` (negated and swapped, to keep ``k1 >= k2``);
* where it disagrees, the normal is flipped, which negates the curvatures once more: our
  ``k1, k2 = k1_cgal, k2_cgal``.

Without given normals each point keeps CGAL's own (arbitrary) normal and the curvatures are
reported relative to it, so only ``k1 * k2`` and ``|k1 + k2|`` mean anything then.

Degree
------
``degree=2`` fits a quadric height function, which is not exact on a sphere: on noise-free
clouds of a few thousand points it overestimates ``1/r`` by a few parts in a thousand. ``degree=4``
is accurate to about 1e-4 there, but it needs 15 neighbors at least and is more sensitive to
noise. The Monge degree is always 2 (only principal curvatures and directions are used).

Examples
--------
>>> from curvature import synthetic
>>> from curvature.studies.peers.cgal import cgal_available, cgal_jet_curvature
>>> cloud = synthetic.sphere(2000, radius=2.0)
>>> if cgal_available():  # doctest: +SKIP
...     k1, k2, normals, status = cgal_jet_curvature(cloud.points, cloud.normals, degree=4)
"""

from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ...errors import CurvatureInputError, ParameterError

__all__ = [
    "CGAL_SOURCE",
    "CgalBuildError",
    "build_cgal_jet",
    "cgal_available",
    "cgal_jet_curvature",
    "cgal_unavailable_reason",
]

#: The C++ driver, in the repository checkout.
CGAL_SOURCE = Path(__file__).resolve().parents[3] / "benchmarks" / "cgal" / "jet_fitting.cpp"

#: Jet degrees :func:`cgal_jet_curvature` accepts (the Monge degree is 2, so at least 2).
JET_DEGREES = (2, 3, 4)

_MONGE_DEGREE = 2
_FIELDS = 6  # k1, k2, nx, ny, nz, condition number per point, as the driver writes them
_MAGIC_IN = b"CGJETIN1"
_MAGIC_OUT = b"CGJETOU1"
# EIGEN_NO_DEBUG drops Eigen's index checks (they abort); CGAL's own checks stay on and throw.
_CXX_FLAGS = ("-O2", "-std=c++17", "-DEIGEN_NO_DEBUG", "-DCGAL_EIGEN3_ENABLED", "-pthread")
_INSTALL_HINT = "on Debian: apt-get install libcgal-dev libeigen3-dev g++"


class CgalBuildError(RuntimeError):
    """The C++ driver could not be compiled; the message holds the compiler's output."""


def _include_dirs() -> list[Path]:
    """Folders searched for CGAL's and Eigen's headers: ``CPATH`` first, then the usual ones."""
    extra = [Path(p) for p in os.environ.get("CPATH", "").split(os.pathsep) if p]
    return extra + [Path("/usr/local/include"), Path("/usr/include")]


def _find_header(relative: str, subdirs: tuple[str, ...] = ("",)) -> Path | None:
    """The include folder holding ``relative`` (trying each of ``subdirs``), or None."""
    for base in _include_dirs():
        for sub in subdirs:
            folder = base / sub if sub else base
            if (folder / relative).is_file():
                return folder
    return None


def _compiler() -> str | None:
    """Path of the C++ compiler: ``$CXX``, else ``g++``, else ``c++``."""
    cxx = os.environ.get("CXX")
    if cxx:
        return shutil.which(cxx)
    return shutil.which("g++") or shutil.which("c++")


def cgal_unavailable_reason() -> str | None:
    """Why :func:`build_cgal_jet` cannot work here, or None when everything it needs is present.

    Returns
    -------
    str or None
        The first missing piece (driver source, C++ compiler, CGAL or Eigen headers) with how to
        install it.
    """
    if not CGAL_SOURCE.is_file():
        return f"the CGAL driver source {CGAL_SOURCE} is missing (it lives in the repository)"
    if _compiler() is None:
        return f"no C++ compiler found (tried $CXX, g++, c++); {_INSTALL_HINT}"
    if _find_header("CGAL/Monge_via_jet_fitting.h") is None:
        return f"CGAL headers not found (CGAL/Monge_via_jet_fitting.h); {_INSTALL_HINT}"
    if _find_header("Eigen/Core", ("eigen3", "")) is None:
        return f"Eigen headers not found (eigen3/Eigen/Core); {_INSTALL_HINT}"
    return None


def cgal_available() -> bool:
    """Whether the CGAL reference can be built: source, compiler and headers are present.

    :func:`cgal_unavailable_reason` says what is missing when this is False.

    Returns
    -------
    bool
    """
    return cgal_unavailable_reason() is None


def _cache_dir() -> Path:
    """``$XDG_CACHE_HOME/curvature/cgal`` (``~/.cache/curvature/cgal`` by default)."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "curvature" / "cgal"


def _command(cxx: str, source: Path, target: Path) -> list[str]:
    eigen = _find_header("Eigen/Core", ("eigen3", ""))
    includes = [f"-I{eigen}"] if eigen is not None else []
    return [cxx, *_CXX_FLAGS, *includes, str(source), "-o", str(target)]


def build_cgal_jet(cache_dir=None) -> Path:
    """Compile the jet-fitting driver once and return the executable's path.

    The executable's name carries a hash of the source and of the compile command, so an edited
    source or another compiler builds anew and an unchanged one is reused (about 20 s to build).
    It is written under a temporary name and renamed, so concurrent builds never see half a file.

    Parameters
    ----------
    cache_dir : str or os.PathLike, optional
        Where to keep the executable; default ``$XDG_CACHE_HOME/curvature/cgal``.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    CgalBuildError
        Something needed is missing (the message says what and how to install it), or the
        compiler failed (the message holds its output).
    """
    reason = cgal_unavailable_reason()
    if reason is not None:
        raise CgalBuildError(f"cannot build the CGAL jet-fitting driver: {reason}")
    cxx = _compiler()
    folder = Path(cache_dir) if cache_dir is not None else _cache_dir()
    probe = _command(cxx, CGAL_SOURCE, Path("OUT"))
    digest = hashlib.sha256(CGAL_SOURCE.read_bytes())
    digest.update("\0".join(probe).encode())
    target = folder / f"jet_fitting-{digest.hexdigest()[:16]}"
    if target.is_file() and os.access(target, os.X_OK):
        return target
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=target.name + ".", suffix=".tmp", dir=folder)
    os.close(fd)
    tmp = Path(tmp_name)
    cmd = _command(cxx, CGAL_SOURCE, tmp)
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise CgalBuildError(
                f"compiling {CGAL_SOURCE.name} failed (exit {proc.returncode}): "
                f"{shlex.join(cmd)}\n{proc.stderr.strip() or proc.stdout.strip()}")
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return target


def _as_xyz(values, name: str) -> np.ndarray:
    """``values`` as a C-contiguous little-endian float64 (n, 3) array of finite numbers."""
    arr = np.ascontiguousarray(values, dtype="<f8")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise CurvatureInputError(f"{name} must have shape (n, 3), got {arr.shape}")
    if not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise CurvatureInputError(f"{name} must be finite; row {bad} is not")
    return arr


def _check_params(n: int, k, degree, workers) -> tuple[int, int, int]:
    """Validated ``(k, degree, workers)``; raises ParameterError naming the bad one."""
    if n < 10:
        raise CurvatureInputError(f"a curvature estimate needs at least 10 points, got {n}")
    if degree not in JET_DEGREES:
        raise ParameterError(f"degree must be one of {list(JET_DEGREES)}, got {degree!r}")
    needed = (degree + 1) * (degree + 2) // 2  # coefficients of a bivariate jet of that degree
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < needed:
        raise ParameterError(
            f"k must be an integer of at least {needed} (the coefficients of a degree-{degree}"
            f" jet), got {k!r}")
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise ParameterError(f"workers must be a positive integer, got {workers!r}")
    return int(k), int(degree), int(workers)


def _run_driver(exe: Path, points: np.ndarray, k: int, degree: int, workers: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Run the driver on ``points``; return its (n, 6) float64 values and (n,) int8 status."""
    n = points.shape[0]
    header = np.array([n, k, degree, _MONGE_DEGREE, workers], dtype="<i8")
    proc = subprocess.run([str(exe)], input=_MAGIC_IN + header.tobytes() + points.tobytes(),
                          capture_output=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"the CGAL jet-fitting driver {exe} failed (exit {proc.returncode}): "
                           f"{proc.stderr.decode(errors='replace').strip()}")
    out = proc.stdout
    body = 8 * _FIELDS * n
    if (len(out) != 16 + body + n or out[:8] != _MAGIC_OUT
            or int(np.frombuffer(out, "<i8", 1, 8)[0]) != n):
        raise RuntimeError(f"the CGAL jet-fitting driver {exe} wrote {len(out)} bytes, not the "
                           f"{16 + body + n} expected for {n} points")
    values = np.frombuffer(out, "<f8", _FIELDS * n, 16).reshape(n, _FIELDS)
    status = np.frombuffer(out, np.int8, n, 16 + body).copy()
    return values, status


def cgal_jet_curvature(points, normals=None, k: int = 24, degree: int = 2, workers=None, *,
                       cache_dir=None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Principal curvatures by CGAL's jet fitting over ``k`` nearest points, in our convention.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        At least 10 finite points.
    normals : array_like, shape (n, 3), optional
        Reference normals that only orient the result (each fitted normal is flipped to agree
        with its reference, and the curvature signs follow it); they do not enter the fit.
        Without them CGAL's arbitrary per-point sign is kept (see the module docstring).
    k : int
        Neighbors per fit, the point itself included; at least the jet's coefficient count
        (6 for degree 2, 10 for 3, 15 for 4). Clouds smaller than ``k`` use all their points.
    degree : {2, 3, 4}
        Degree of the fitted jet; the Monge form read off it is of degree 2.
    workers : int, optional
        Threads of the driver; default ``os.cpu_count()``. Results do not depend on it.
    cache_dir : str or os.PathLike, optional
        Passed to :func:`build_cgal_jet`.

    Returns
    -------
    k1, k2 : ndarray, shape (n,), float64
        Signed principal curvatures, ``k1 >= k2``, positive where the surface bends away from
        the returned normal; NaN where ``status != 0``.
    normals : ndarray, shape (n, 3), float64
        CGAL's fitted unit normals, oriented like the reference normals; NaN where
        ``status != 0``.
    status : ndarray, shape (n,), int8
        0 ok, 1 too few neighbors, 2 degenerate fit (CGAL rejected it, or its condition
        number is above 1e10 or not finite: collinear or coincident neighbors), 4 non-finite
        result.

    Raises
    ------
    CurvatureInputError
        Bad shapes, non-finite values or fewer than 10 points.
    ParameterError
        ``k``, ``degree`` or ``workers`` out of range.
    CgalBuildError
        The driver cannot be built here (see :func:`build_cgal_jet`).
    RuntimeError
        The driver failed or wrote something unexpected (its message is included).
    """
    pts = _as_xyz(points, "points")
    ref = None
    if normals is not None:
        ref = _as_xyz(normals, "normals")
        if ref.shape != pts.shape:
            raise CurvatureInputError(f"normals must have shape {pts.shape}, got {ref.shape}")
    k, degree, workers = _check_params(pts.shape[0], k, degree, workers)
    values, status = _run_driver(build_cgal_jet(cache_dir), pts, k, degree, workers)
    ck1, ck2, monge = values[:, 0], values[:, 1], values[:, 2:5]
    agrees = (np.ones(len(pts), bool) if ref is None
              else np.einsum("ij,ij->i", monge, ref) >= 0.0)
    # CGAL's curvatures are positive towards its normal, ours away from the oriented one.
    k1 = np.where(agrees, -ck2, ck1)
    k2 = np.where(agrees, -ck1, ck2)
    out_normals = np.where(agrees[:, None], monge, -monge)
    failed = status != 0
    k1[failed] = np.nan
    k2[failed] = np.nan
    out_normals[failed] = np.nan
    return k1, k2, out_normals, status
