"""Mesh formats read through trimesh: GLB / glTF 2.0 and 3MF.

trimesh parses these container formats (binary chunks, JSON, zipped XML, scene graphs with
instancing); our own readers keep OBJ, STL and OFF, whose errors name the line or byte and
which read without a per-vertex Python loop (tests check them against trimesh's files). Mesh
connectivity stays ours too: :func:`curvature.neighborhoods.connectivity.face_graph` built
the vertex graph of a 163,842-vertex sphere 5.7 times faster than trimesh's unique edges
(``benchmarks/mesh_graph.py``, medians of 5). Before anything goes to trimesh the sizes the
file claims are checked against its real size, so a lying header or a zip or instancing bomb
is refused before memory is allocated for it: accessors must fit in their buffer views and
buffers in the file, zip members may not inflate beyond :data:`MAX_INFLATE` times the file,
and the scene may not instance more output than :data:`MAX_OUTPUT_RATIO` times the file.
Every trimesh exception becomes a :class:`~curvature.errors.FormatError` naming the file.

Scene nodes' transforms are applied and every mesh of the scene is kept, in one cloud;
vertices with identical coordinates (glTF splits them at seams) are merged so that faces
share them, like an STL's corners. Vertex colours come back as ``red green blue alpha``.
"""

from __future__ import annotations

import base64
import binascii
import io
import json
import struct
import zipfile
import zlib
from xml.etree.ElementTree import ParseError, iterparse

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud
from .meshes import merge_identical

GLB_MAGIC = b"glTF"
GLB_JSON, GLB_BIN = 0x4E4F534A, 0x004E4942
COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
TYPE_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
# Zip members may inflate to at most this many times the file (XML compresses about 10x).
MAX_INFLATE = 200
# The scene's instanced output (vertices and triangles, as float64/int64 rows) may be at
# most this many times the file's size.
MAX_OUTPUT_RATIO = 64
OUTPUT_ROW_BYTES = 24


def _trimesh(source):
    try:
        import trimesh
    except ImportError:  # pragma: no cover - trimesh is a core dependency
        raise FormatError(source, "reading meshes needs trimesh (pip install trimesh)") from None
    return trimesh


# --- size checks ---------------------------------------------------------------------------

def _glb_chunks(data: bytes, source) -> tuple[dict, int]:
    """The JSON of a GLB and the length of its binary chunk (0 without one)."""
    if len(data) < 20 or data[:4] != GLB_MAGIC:
        raise FormatError(source, "not a GLB file: it must start with 'glTF' and a 12-byte "
                                  "header", offset=0)
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise FormatError(source, f"GLB version {version}; only glTF 2.0 is read", offset=4)
    if length != len(data):
        raise FormatError(source, f"the GLB header says {length} bytes but the file has "
                                  f"{len(data)}: truncated or padded", offset=8)
    chunk_len, chunk_type = struct.unpack_from("<II", data, 12)
    if chunk_type != GLB_JSON or 20 + chunk_len > len(data):
        raise FormatError(source, f"the first GLB chunk must be JSON within the file "
                                  f"({chunk_len} bytes claimed)", offset=12)
    doc = _json(data[20:20 + chunk_len], source)
    at = 20 + chunk_len
    bin_len = 0
    if at + 8 <= len(data):
        bin_len, bin_type = struct.unpack_from("<II", data, at)
        if bin_type != GLB_BIN or at + 8 + bin_len > len(data):
            raise FormatError(source, f"the second GLB chunk must be BIN within the file "
                                      f"({bin_len} bytes claimed)", offset=at)
    return doc, bin_len


def _json(text: bytes, source) -> dict:
    try:
        doc = json.loads(text)
    except (ValueError, UnicodeError) as exc:
        raise FormatError(source, f"the glTF JSON does not parse: {exc}") from None
    if not isinstance(doc, dict):
        raise FormatError(source, "the glTF JSON must be an object")
    return doc


def _buffer_sizes(doc: dict, bin_len: int, source) -> list[int]:
    """Bytes really available to each buffer: the GLB chunk, or an embedded data URI."""
    sizes = []
    for i, buf in enumerate(_list(doc, "buffers", source)):
        uri = buf.get("uri")
        if uri is None:
            have = bin_len
        elif isinstance(uri, str) and uri.startswith("data:") and "," in uri:
            try:
                have = len(base64.b64decode(uri.split(",", 1)[1], validate=True))
            except (binascii.Error, ValueError):
                raise FormatError(source, f"buffer {i}: its data URI is not base64") from None
        else:
            raise FormatError(source, f"buffer {i} refers to the external file {str(uri)[:80]!r}; "
                                      "only GLB or a .gltf with embedded buffers is read")
        claimed = _count(buf.get("byteLength"), f"buffer {i} byteLength", source)
        if claimed > have:
            raise FormatError(source, f"buffer {i} claims {claimed} bytes but holds {have}")
        sizes.append(claimed)
    return sizes


def _list(doc: dict, key: str, source) -> list:
    items = doc.get(key, [])
    if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
        raise FormatError(source, f"the glTF '{key}' must be a list of objects")
    return items


def _count(value, what: str, source) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise FormatError(source, f"{what} must be a whole number >= 0, got {value!r}")
    return value


def check_gltf(doc: dict, bin_len: int, size: int, source) -> None:
    """Check that every accessor fits its buffer view, every view its buffer, every buffer
    the file, and that the scene does not instance unbounded output.

    Raises
    ------
    FormatError
        Names the accessor, view or buffer that claims more than the file holds.
    """
    buffers = _buffer_sizes(doc, bin_len, source)
    views = _list(doc, "bufferViews", source)
    for i, view in enumerate(views):
        b = view.get("buffer")
        if not isinstance(b, int) or not 0 <= b < len(buffers):
            raise FormatError(source, f"bufferView {i} names buffer {b!r}, which does not exist")
        end = _count(view.get("byteOffset", 0), f"bufferView {i} byteOffset", source) + \
            _count(view.get("byteLength"), f"bufferView {i} byteLength", source)
        if end > buffers[b]:
            raise FormatError(source, f"bufferView {i} ends at byte {end} of buffer {b}, which "
                                      f"holds {buffers[b]}")
    accessors = _list(doc, "accessors", source)
    for i, acc in enumerate(accessors):
        if "sparse" in acc or "bufferView" not in acc:
            raise FormatError(source, f"accessor {i} has no bufferView (sparse or zero-filled "
                                      "accessors are not read)")
        v = acc["bufferView"]
        if not isinstance(v, int) or not 0 <= v < len(views):
            raise FormatError(source, f"accessor {i} names bufferView {v!r}, which does not "
                                      "exist")
        item = COMPONENT_BYTES.get(acc.get("componentType"), 0) * \
            TYPE_WIDTH.get(acc.get("type"), 0)
        if item == 0:
            raise FormatError(source, f"accessor {i} has an unknown componentType or type")
        count = _count(acc.get("count"), f"accessor {i} count", source)
        stride = views[v].get("byteStride") or item
        need = _count(acc.get("byteOffset", 0), f"accessor {i} byteOffset", source) + \
            (stride * (count - 1) + item if count else 0)
        if need > views[v]["byteLength"]:
            raise FormatError(source, f"accessor {i} needs {need} bytes ({count} items) but "
                                      f"bufferView {v} holds {views[v]['byteLength']}")
    rows = _instanced_rows(doc, accessors, source)
    _check_output(rows, size, source)


def _mesh_rows(mesh: dict, accessors: list) -> int:
    """Vertex plus triangle rows one instance of a glTF mesh produces."""
    rows = 0
    for prim in mesh.get("primitives", []) if isinstance(mesh, dict) else []:
        attrs = prim.get("attributes", {}) if isinstance(prim, dict) else {}
        for ref, per_row in ((attrs.get("POSITION"), 1), (prim.get("indices"), 3)):
            if isinstance(ref, int) and 0 <= ref < len(accessors):
                rows += int(accessors[ref].get("count", 0)) // per_row
    return rows


def _instanced_rows(doc: dict, accessors: list, source) -> int:
    """Output rows of the whole scene, every node path to a mesh counted once (instancing)."""
    nodes = _list(doc, "nodes", source)
    meshes = doc.get("meshes", [])
    memo: dict[int, int] = {}

    def rows(i: int, path: frozenset) -> int:
        if not isinstance(i, int) or not 0 <= i < len(nodes):
            raise FormatError(source, f"a scene names node {i!r}, which does not exist")
        if i in path:
            raise FormatError(source, f"node {i} is its own ancestor: the node graph has a "
                                      "cycle")
        if i not in memo:
            node = nodes[i]
            m = node.get("mesh")
            total = _mesh_rows(meshes[m], accessors) if isinstance(m, int) and \
                0 <= m < len(meshes) else 0
            for child in node.get("children", []):
                total += rows(child, path | {i})
            memo[i] = total
        return memo[i]

    scenes = _list(doc, "scenes", source)
    roots = [r for s in scenes for r in s.get("nodes", [])] if scenes else range(len(nodes))
    return sum(rows(r, frozenset()) for r in roots)


def _check_output(rows: int, size: int, source) -> None:
    if rows * OUTPUT_ROW_BYTES > MAX_OUTPUT_RATIO * size:
        raise FormatError(source, f"the scene instances {rows:,} vertex and triangle rows from "
                                  f"a {size:,}-byte file; more than {MAX_OUTPUT_RATIO} bytes "
                                  "of output per byte of file is refused")


def check_3mf(data: bytes, source) -> None:
    """Check a 3MF package: a zip whose members inflate to a bounded size, whose build
    instances a bounded number of vertices and triangles (components included)."""
    try:
        package = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise FormatError(source, "not a 3MF file: a 3MF package is a zip archive",
                          offset=0) from None
    with package:
        infos = package.infolist()
        inflated = sum(i.file_size for i in infos)
        if inflated > MAX_INFLATE * len(data):
            raise FormatError(source, f"the zip members inflate to {inflated:,} bytes, more "
                                      f"than {MAX_INFLATE} times the {len(data):,}-byte file")
        models = [i for i in infos if i.filename.lower().endswith(".model")]
        if not models:
            raise FormatError(source, "the 3MF package holds no .model part")
        own, refs, items = {}, {}, []
        for info in models:
            try:
                with package.open(info) as fh:
                    _scan_model(fh, own, refs, items)
            except (ParseError, zipfile.BadZipFile, zlib.error, EOFError) as exc:
                raise FormatError(source, f"{info.filename}: {exc}") from None
    memo: dict[str, int] = {}

    def rows(obj: str, path: frozenset) -> int:
        if obj in path:
            raise FormatError(source, f"object {obj} contains itself (a component cycle)")
        if obj not in memo:
            memo[obj] = own.get(obj, 0) + sum(rows(r, path | {obj}) for r in refs.get(obj, []))
        return memo[obj]

    _check_output(sum(rows(i, frozenset()) for i in items), len(data), source)


def _scan_model(fh, own: dict, refs: dict, items: list) -> None:
    """Vertex and triangle counts per object, its components and the build items."""
    current = None
    for event, el in iterparse(fh, events=("start", "end")):
        tag = el.tag.rsplit("}", 1)[-1]
        if event == "start" and tag == "object":
            current = el.get("id")
            own.setdefault(current, 0)
        elif event == "end":
            if tag in ("vertex", "triangle") and current is not None:
                own[current] += 1
            elif tag == "component" and current is not None:
                refs.setdefault(current, []).append(el.get("objectid"))
            elif tag == "item":
                items.append(el.get("objectid"))
            elif tag == "object":
                current = None
            el.clear()


# --- reading -------------------------------------------------------------------------------

def read_glb(data: bytes, source=None) -> PointCloud:
    """Decode a binary glTF 2.0 (GLB) file: every mesh of its scene, transforms applied."""
    doc, bin_len = _glb_chunks(data, source)
    check_gltf(doc, bin_len, len(data), source)
    return _load(data, "glb", source)


def read_gltf(data: bytes, source=None) -> PointCloud:
    """Decode a glTF 2.0 JSON file whose buffers are embedded (base64 data URIs)."""
    check_gltf(_json(data, source), 0, len(data), source)
    return _load(data, "gltf", source)


def read_3mf(data: bytes, source=None) -> PointCloud:
    """Decode a 3MF package: every build item's mesh, components and transforms applied."""
    check_3mf(data, source)
    return _load(data, "3mf", source)


def _load(data: bytes, fmt: str, source) -> PointCloud:
    trimesh = _trimesh(source)
    try:
        scene = trimesh.load_scene(io.BytesIO(data), file_type=fmt, process=False)
        meshes = list(scene.dump()) if len(scene.geometry) else []
    except FormatError:
        raise
    except ImportError as exc:
        raise FormatError(source, f"reading {fmt} needs {exc.name or 'a missing package'} "
                                  "(pip install 'curvature[formats]')") from None
    except Exception as exc:  # trimesh raises many kinds; the user needs the file and why
        raise FormatError(source, f"could not read as {fmt}: {type(exc).__name__}: "
                                  f"{str(exc)[:300]}") from None
    meshes = [m for m in meshes if isinstance(m, trimesh.Trimesh) and len(m.vertices)]
    if not meshes:
        raise FormatError(source, "the file holds no triangle mesh")
    return _merged_cloud(meshes, source)


def _merged_cloud(meshes: list, source) -> PointCloud:
    """One cloud of all meshes: identical vertices merged, faces re-indexed, colours kept."""
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    points = np.concatenate([np.asarray(m.vertices, np.float64) for m in meshes])
    faces = np.concatenate([np.asarray(m.faces, np.int64) + o for m, o in
                            zip(meshes, offsets, strict=True)])
    colours = None
    if all(m.visual.kind == "vertex" for m in meshes):
        colours = np.concatenate([np.asarray(m.visual.vertex_colors, np.uint8)
                                  for m in meshes])
    unique, first, inverse = merge_identical(points)
    props = {} if colours is None else {
        name: colours[first, j] for j, name in enumerate(("red", "green", "blue", "alpha"))}
    cloud = finish_cloud(source, unique, properties=props, label="vertex")
    cloud.faces = inverse[faces] if faces.size else None
    return cloud
