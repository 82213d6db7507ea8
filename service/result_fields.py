"""One field of a finished job at a time, for the web viewer: float32 arrays and single points.

The canonical result (``result.npz``, uncompressed) is read in place: each array's bytes are
mapped from the archive (``np.memmap`` at the member's offset), so a field is converted in
chunks and one point's values are a few page reads, whatever the cloud's size. The fields
are those of the JSON result, in its order (:func:`curvature.io.table_of`): positions, the
result's arrays (any new array such as ``k1_std`` included), shape index and curvedness,
``index`` and the input's attributes (packed colours as channels).

Converted fields are cached in the job's folder (``fields/<name>.f32``, little-endian
float32, row-major); ``fields/manifest.json`` lists them with the canonical file's size and
modification time at the moment its checksum was verified, so later requests need only a
``stat`` to know the archive is the one verified.
"""

from __future__ import annotations

import json
import os
import struct
import uuid
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import curvature
import curvature.io

from .result_files import ATTRIBUTE_PREFIX, CANONICAL_RESULT, ResultCorrupt, matches

FIELDS_DIR = "fields"
MANIFEST = "manifest.json"
CHUNK_ROWS = 1 << 18  # rows converted at once: 262,144 x 3 x 8 bytes = 6 MB at most
FLOAT32 = np.dtype("<f4")
_LOCAL_HEADER = struct.Struct("<IHHHHHIIIHH")  # a zip member's local file header (30 bytes)
_NOT_FIELDS = {"info", "faces"}


@dataclass(frozen=True)
class Member:
    """An array stored uncompressed in an NPZ: where its data starts and what it holds."""

    dtype: np.dtype
    shape: tuple[int, ...]
    offset: int

    def array(self, path: Path) -> np.ndarray:
        """The array mapped read-only from the file (nothing is read until sliced)."""
        if 0 in self.shape:
            return np.empty(self.shape, self.dtype)
        return np.memmap(path, dtype=self.dtype, mode="r", offset=self.offset,
                         shape=self.shape)


def npz_members(path: Path) -> dict[str, Member]:
    """The arrays of an uncompressed NPZ with their data offsets, from the headers alone.

    Raises
    ------
    ResultCorrupt
        The archive cannot be read, a member is compressed, not C-ordered or holds objects.
    """
    members = {}
    try:
        with open(path, "rb") as fh, zipfile.ZipFile(fh) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                name = info.filename[:-4]
                if info.compress_type != zipfile.ZIP_STORED:
                    raise ResultCorrupt(f"{CANONICAL_RESULT}: {name} is compressed")
                fh.seek(info.header_offset)
                header = _LOCAL_HEADER.unpack(fh.read(_LOCAL_HEADER.size))
                fh.seek(info.header_offset + _LOCAL_HEADER.size + header[9] + header[10])
                version = np.lib.format.read_magic(fh)
                readers = {(1, 0): np.lib.format.read_array_header_1_0,
                           (2, 0): np.lib.format.read_array_header_2_0}
                if version not in readers:
                    raise ResultCorrupt(f"{CANONICAL_RESULT}: {name} has npy format {version}")
                shape, fortran, dtype = readers[version](fh)
                if fortran or dtype.hasobject:
                    raise ResultCorrupt(f"{CANONICAL_RESULT}: {name} is not a plain C array")
                members[name] = Member(dtype=dtype, shape=tuple(shape), offset=fh.tell())
    except (OSError, zipfile.BadZipFile, ValueError, struct.error) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise ResultCorrupt(f"{CANONICAL_RESULT} cannot be read: {exc}") from None
    return members


@dataclass(frozen=True)
class Field:
    """One field of the viewer: its name and how to compute rows of it from the archive."""

    name: str
    components: int
    rows: Callable[[int, int], np.ndarray]  # (start, stop) -> (m,) or (m, components)
    dtype: str  # of the stored values: "float64", "int8", "uint8" ...


def _colour_channels(attributes: dict[str, np.ndarray]) -> dict[str, tuple[str, str]]:
    """Output name -> (attribute, channel) for packed colours, as the result files expand
    them (``rgba`` -> ``red green blue alpha``); decided from dtypes alone."""
    empty = {k: np.empty(0, dtype=v.dtype) for k, v in attributes.items() if v.ndim == 1}
    expanded = curvature.io.expand_colors(empty)
    packed = [k for k in empty if k not in expanded]
    return {name: (packed[0], name) for name in expanded if name not in empty} if packed else {}


def catalog(path: Path) -> tuple[int, dict[str, Field]]:
    """The fields of a canonical result, in the JSON result's order.

    Returns
    -------
    n : int
        Number of points.
    fields : dict of str to Field
    """
    members = npz_members(path)
    if "points" not in members or len(members["points"].shape) != 2:
        raise ResultCorrupt(f"{CANONICAL_RESULT} has no points array")
    n = members["points"].shape[0]
    arrays = {k: m.array(path) for k, m in members.items() if k not in _NOT_FIELDS}
    own = {k: a for k, a in arrays.items() if not k.startswith(ATTRIBUTE_PREFIX)}
    attributes = {k[len(ATTRIBUTE_PREFIX):]: a for k, a in arrays.items()
                  if k.startswith(ATTRIBUTE_PREFIX)}
    fields: dict[str, Field] = {}

    def add(name: str, array: np.ndarray) -> None:
        if array.ndim in (1, 2) and array.shape[0] == n and array.dtype.kind in "biuf":
            width = 1 if array.ndim == 1 else array.shape[1]
            fields[name] = Field(name, width, lambda a, b, x=array: np.asarray(x[a:b]),
                                 str(array.dtype))

    add("points", own["points"])
    order = [k for k in curvature.io.RESULT_ORDER if k in own]
    for name in order + sorted(k for k in own if k not in order and k != "points"):
        add(name, own[name])
    if "k1" in own and "k2" in own:
        k1, k2 = own["k1"], own["k2"]
        derived = {"shape_index": curvature.shape_index, "curvedness": curvature.curvedness}
        for name in curvature.io.DERIVED:
            fields[name] = Field(name, 1, lambda a, b, f=derived[name]: f(k1[a:b], k2[a:b]),
                                 "float64")
    if "index" in attributes:
        add("index", attributes.pop("index"))
    else:
        fields["index"] = Field("index", 1, lambda a, b: np.arange(a, min(b, n)), "int64")
    channels = _colour_channels(attributes)
    packed = {source for source, _ in channels.values()}
    for name, array in attributes.items():
        if name in packed:
            for out, (source, channel) in channels.items():
                fields[out] = Field(out, 1, lambda a, b, k=source, c=channel: curvature.io
                                    .expand_colors({k: np.asarray(attributes[k][a:b])})[c],
                                    "uint8")
        elif name not in fields:
            add(name, array)
    return n, fields


def describe(field: Field) -> dict:
    """The listing entry of a field: name, components, stored dtype, label, unit, scale."""
    info = curvature.describe_field(field.name)
    entry = {"name": field.name, "components": field.components, "dtype": field.dtype,
             "label": info.label, "unit": info.unit, "scale": info.scale}
    if info.limits is not None:
        entry["limits"] = list(info.limits)
    if info.categories is not None:
        entry["categories"] = {str(k): v for k, v in info.categories.items()}
    return entry


def _stamp(path: Path) -> list[int]:
    st = path.stat()
    return [st.st_size, st.st_mtime_ns, st.st_ino]


def _atomic_write(target: Path, write: Callable) -> None:
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "wb") as fh:
            write(fh)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def manifest(job_dir: Path, canonical_sha256: str | None = None) -> dict:
    """The job's field listing, written after the canonical file's checksum is verified.

    Returns
    -------
    dict
        ``n``, ``up`` (the automatic up direction, a unit 3-vector), ``fields`` (listing
        entries) and ``stamp`` (the canonical file's size, mtime and inode when verified).

    Raises
    ------
    FileNotFoundError
        The job's files are gone.
    ResultCorrupt
        The canonical file fails its checksum or cannot be read.
    """
    canonical = job_dir / CANONICAL_RESULT
    target = job_dir / FIELDS_DIR / MANIFEST
    stamp = _stamp(canonical)
    try:
        doc = json.loads(target.read_text())
        if doc.get("stamp") == stamp and doc.get("sha256") == canonical_sha256:
            return doc
    except (OSError, ValueError):
        pass
    if not matches(canonical, canonical_sha256):
        if not canonical.exists():
            raise FileNotFoundError(2, "No such file", str(canonical))
        raise ResultCorrupt(f"{CANONICAL_RESULT} fails its checksum")
    n, fields = catalog(canonical)
    # The cached conversions belong to the archive verified now, not to an older one.
    folder = job_dir / FIELDS_DIR
    folder.mkdir(exist_ok=True)
    for old in folder.glob("*.f32"):
        old.unlink(missing_ok=True)
    points = npz_members(canonical)["points"].array(canonical)  # auto_up reads a subsample
    up = curvature.auto_up(points)
    doc = {"n": n, "up": [float(c) for c in up], "fields": [describe(f) for f in fields.values()],
           "stamp": stamp, "sha256": canonical_sha256}
    _atomic_write(target, lambda fh: fh.write(json.dumps(doc).encode()))
    return doc


def field_file(job_dir: Path, name: str, canonical_sha256: str | None = None) -> tuple[Path, dict]:
    """The cached float32 file of one field (converted on first request) and its listing entry.

    Raises
    ------
    KeyError
        The result has no such field.
    FileNotFoundError, ResultCorrupt
        As :func:`manifest`.
    """
    doc = manifest(job_dir, canonical_sha256)
    entry = next((f for f in doc["fields"] if f["name"] == name), None)
    if entry is None:
        raise KeyError(name)
    target = job_dir / FIELDS_DIR / f"{name}.f32"
    if not target.exists():
        n, fields = catalog(job_dir / CANONICAL_RESULT)
        rows = fields[name].rows

        def write(fh):
            for start in range(0, n, CHUNK_ROWS):
                fh.write(np.ascontiguousarray(rows(start, start + CHUNK_ROWS),
                                              dtype=FLOAT32).tobytes())

        _atomic_write(target, write)
    return target, entry


def _plain(value):
    """A JSON value: NaN and infinities as None, numpy scalars as Python numbers."""
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value.item() if isinstance(value, np.generic) else value


def point_values(job_dir: Path, index: int, canonical_sha256: str | None = None) -> dict:
    """Every field of one point, exactly as stored (float64 where the result has it).

    Raises
    ------
    IndexError
        ``index`` is not a point of the result (the message says the valid range).
    FileNotFoundError, ResultCorrupt
        As :func:`manifest`.
    """
    doc = manifest(job_dir, canonical_sha256)
    n = doc["n"]
    if not 0 <= index < n:
        raise IndexError(f"point index {index} is out of range: the result has {n} points "
                         f"(0 to {n - 1})")
    _, fields = catalog(job_dir / CANONICAL_RESULT)
    return {name: _plain(field.rows(index, index + 1)[0]) for name, field in fields.items()}
