"""Reading a cloud from a request: streamed multipart upload or JSON arrays.

File uploads are parsed as they arrive and written to the job folder in chunks, so a large
scan never sits whole in memory, and the size limit is enforced while streaming (413 as soon as
it is exceeded, or before reading anything when Content-Length already says so). JSON bodies
are parsed in memory, under their own smaller limit, off the event loop.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio.to_thread
import numpy as np
from fastapi import Request
from pydantic import TypeAdapter, ValidationError
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import ClientDisconnect

from .formats import INPUT_EXTENSIONS, extension_of
from .input_guard import check_numpy_file
from .inputs import CloudInput, check_cloud
from .json_count import scan_members
from .param_errors import parameter_message
from .problem_types import ProblemError
from .problems import HTTPProblem, validation_errors
from .schemas import METHOD_MODELS, MethodParams, default_params
from .settings import Settings
from .upload_gate import gate_of, timed_stream

_PARAMS_ADAPTER: TypeAdapter = TypeAdapter(MethodParams)
_MAX_PARAMS_BYTES = 64 * 1024
_FLUSH_BYTES = 1 << 20
_JSON_KEYS = {"points", "normals", "faces", "params"}
UPLOAD_PART = ".upload.part"


@dataclass
class ReceivedInput:
    """A cloud stored in ``folder``, ready for a worker.

    Attributes
    ----------
    kind : {"file", "arrays"}
        An uploaded file (read by the library) or JSON arrays (stored as NPZ).
    input_file : str
        File name inside the folder.
    filename, format : str or None
        The client's file name and its format (extension).
    size : int
        Bytes received.
    params : dict
        Validated method and fit parameters (JSON form, defaults filled in).
    n_points : int or None
        Known for arrays; for files once a worker has read them.
    """

    kind: str
    input_file: str
    filename: str | None
    format: str | None
    size: int
    params: dict
    n_points: int | None = None


def parse_json(raw: bytes, slug: str, what: str) -> Any:
    """Decode JSON from a client; every way it can fail is a ``slug`` problem.

    Besides syntax errors this covers nesting deeper than the parser's recursion limit and
    integers longer than Python converts (both raise other exceptions than JSONDecodeError).
    Memory stays bounded by the body limit the caller enforced.
    """
    try:
        return json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise HTTPProblem(slug, f"{what}: not valid JSON ({exc})") from None
    except RecursionError:
        raise HTTPProblem(slug, f"{what}: JSON nested too deeply") from None
    except ValueError as exc:  # e.g. an integer literal of more than 4300 digits
        raise HTTPProblem(slug, f"{what}: a JSON value cannot be read ({exc})") from None


def parse_params(raw: Any) -> dict:
    """Validate method and fit parameters; ``None`` gives the defaults."""
    if raw is None:
        return default_params().model_dump(mode="json")
    try:
        model = _PARAMS_ADAPTER.validate_python(raw)
    except ValidationError as exc:
        raw_errors = exc.errors(include_url=False, include_input=False)
        detail = parameter_message(raw, raw_errors[0])
        for err in raw_errors:
            # A discriminated union puts the method tag first in loc; the client did not
            # write it, so drop it ("params.k", not "params.knn.k").
            if err["loc"] and err["loc"][0] in METHOD_MODELS:
                err["loc"] = err["loc"][1:]
        errors = validation_errors(raw_errors, ("params",))
        raise HTTPProblem("invalid-parameters", f"{'.'.join(errors[0]['loc'])}: {detail}",
                          errors=errors) from None
    return model.model_dump(mode="json")


def _check_declared_length(request: Request, limit: int) -> None:
    declared = request.headers.get("content-length", "").strip()
    # ASCII digits only, and few enough for int(): the server rejects other values anyway.
    if declared.isascii() and declared.isdigit() and (len(declared) > 18
                                                      or int(declared) > limit):
        raise HTTPProblem("too-large", f"the body announces {declared} bytes; the limit is "
                          f"{limit} bytes")


async def receive_cloud(request: Request, folder: Path, settings: Settings,
                        owner: str = "anonymous") -> ReceivedInput:
    """Store the request's cloud in ``folder`` (which must exist) and validate parameters.

    Raises
    ------
    HTTPProblem
        413 too large, 415 unknown file format or unsupported media type, 400 malformed body,
        422 invalid parameters or cloud, 408 too slow, 429/503 too many uploads at once
        (:mod:`service.upload_gate`).
    """
    content_type, options = parse_options_header(request.headers.get("content-type"))
    try:
        if content_type == b"multipart/form-data":
            with gate_of(request).hold(owner, settings.retry_after_seconds):
                return await _receive_multipart(request, folder, options.get(b"boundary"),
                                                settings)
        if content_type == b"application/json" or content_type.endswith(b"+json"):
            with gate_of(request).hold(owner, settings.retry_after_seconds):
                return await _receive_json(request, folder, settings)
    except ClientDisconnect:
        raise HTTPProblem("malformed-request", "the client disconnected during the upload") \
            from None
    raise HTTPProblem("unsupported-media-type",
                      f"Content-Type {content_type.decode('latin-1') or '(none)'!r} is not "
                      "accepted; send multipart/form-data (file + params) or application/json")


# -- multipart ------------------------------------------------------------------------------

class _MultipartSink:
    """Callbacks of the streaming multipart parser: the file part goes to disk, the rest to
    small in-memory buffers."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.header_field = bytearray()
        self.header_value = bytearray()
        self.headers: dict[bytes, bytes] = {}
        self.part: str | None = None
        self.filename: str | None = None
        self.file_handle = None
        self.file_seen = False
        self.file_bytes = 0
        self.pending = bytearray()  # file data not yet flushed to disk
        self.params: bytearray | None = None
        self.complete = False  # the closing boundary was seen

    def callbacks(self) -> dict:
        return {"on_part_begin": self.on_part_begin, "on_header_field": self.on_header_field,
                "on_header_value": self.on_header_value, "on_header_end": self.on_header_end,
                "on_headers_finished": self.on_headers_finished,
                "on_part_data": self.on_part_data, "on_end": self.on_end}

    def on_part_begin(self) -> None:
        self.headers = {}
        self.part = None

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self.header_field += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self.header_value += data[start:end]

    def on_header_end(self) -> None:
        self.headers[bytes(self.header_field).lower()] = bytes(self.header_value)
        self.header_field.clear()
        self.header_value.clear()

    def on_headers_finished(self) -> None:
        _, disposition = parse_options_header(self.headers.get(b"content-disposition", b""))
        name = disposition.get(b"name", b"").decode("utf-8", "replace")
        if name == "file":
            if self.file_seen:
                raise HTTPProblem("invalid-request", "only one 'file' part is accepted")
            filename = disposition.get(b"filename", b"").decode("utf-8", "replace")
            ext = extension_of(filename)
            if ext not in INPUT_EXTENSIONS:
                raise HTTPProblem("unknown-format", (
                    f"file {filename or '(no name)'!r}: the extension must name a format the "
                    f"service reads: {', '.join(INPUT_EXTENSIONS)}"))
            self.file_seen = True
            self.filename = Path(filename.replace("\\", "/")).name
            self.file_handle = open(self.folder / UPLOAD_PART, "wb")
        elif name == "params":
            if self.params is not None:
                raise HTTPProblem("invalid-request", "only one 'params' part is accepted")
            self.params = bytearray()
        else:
            raise HTTPProblem("invalid-request", f"unexpected form part {name!r}; send 'file' "
                              "and optionally 'params'")
        self.part = name

    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        if self.part == "file":
            self.pending += data[start:end]
            self.file_bytes += end - start
        elif self.part == "params":
            self.params += data[start:end]
            if len(self.params) > _MAX_PARAMS_BYTES:
                raise HTTPProblem("too-large", f"the 'params' part exceeds {_MAX_PARAMS_BYTES} "
                                  "bytes")

    def on_end(self) -> None:
        self.complete = True

    async def flush(self, force: bool = False) -> None:
        if self.file_handle is not None and (force or len(self.pending) >= _FLUSH_BYTES):
            chunk = bytes(self.pending)
            self.pending.clear()
            await anyio.to_thread.run_sync(self.file_handle.write, chunk)

    def close(self) -> None:
        if self.file_handle is not None:
            self.file_handle.close()
            self.file_handle = None


async def _receive_multipart(request: Request, folder: Path, boundary: bytes | None,
                             settings: Settings) -> ReceivedInput:
    limit, max_points = settings.max_upload_bytes, settings.max_points
    _check_declared_length(request, limit)
    if not boundary:
        raise HTTPProblem("malformed-request", "multipart/form-data without a boundary")
    sink = _MultipartSink(folder)
    try:
        parser = MultipartParser(boundary, sink.callbacks())
    except FormParserError as exc:
        raise HTTPProblem("malformed-request", f"bad multipart boundary: {exc}") from None
    received = 0
    try:
        async for chunk in timed_stream(request, settings):
            received += len(chunk)
            if received > limit:
                raise HTTPProblem("too-large", f"the body exceeds the limit of {limit} bytes")
            try:
                parser.write(chunk)
            except FormParserError as exc:
                raise HTTPProblem("malformed-request", f"unreadable multipart body: {exc}") \
                    from None
            await sink.flush()
        try:
            parser.finalize()
        except FormParserError as exc:
            raise HTTPProblem("malformed-request", f"unreadable multipart body: {exc}") from None
        await sink.flush(force=True)
    finally:
        sink.close()
    if not sink.complete:
        raise HTTPProblem("malformed-request", "the multipart body ends before its closing "
                          "boundary (truncated upload?)")
    if not sink.file_seen:
        raise HTTPProblem("invalid-request", "missing form part 'file' (the cloud file)")
    raw_params = None
    if sink.params is not None and sink.params.strip():
        raw_params = parse_json(bytes(sink.params), "invalid-parameters", "params")
    params = parse_params(raw_params)
    ext = extension_of(sink.filename)
    input_file = f"input.{ext}"
    (folder / UPLOAD_PART).replace(folder / input_file)
    try:  # cheap: headers and the zip directory only
        await anyio.to_thread.run_sync(check_numpy_file, folder / input_file, sink.filename,
                                       max_points)
    except ProblemError as exc:
        raise HTTPProblem(exc.slug, exc.detail) from None
    return ReceivedInput(kind="file", input_file=input_file, filename=sink.filename,
                         format=ext, size=sink.file_bytes, params=params)


# -- JSON -----------------------------------------------------------------------------------

async def _read_limited(request: Request, settings: Settings) -> bytes:
    limit = settings.max_json_bytes
    _check_declared_length(request, limit)
    body = bytearray()
    async for chunk in timed_stream(request, settings):
        body += chunk
        if len(body) > limit:
            raise HTTPProblem("too-large", f"the JSON body exceeds the limit of {limit} bytes")
    return bytes(body)


def _as_array(value: Any, name: str, dtype) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError, OverflowError):  # overflow: an integer beyond float range
        raise HTTPProblem("invalid-cloud", f"{name}: expected a list of [x, y, z] number "
                          "triples") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise HTTPProblem("invalid-cloud", f"{name}: expected a list of triples, got shape "
                          f"{arr.shape}")
    return arr


def _decode_cloud(body: bytes, folder: Path, max_points: int | None = None) -> tuple[dict, int]:
    """Parse, check and store the JSON cloud (runs in a thread: it can be big).

    The points are counted on the raw bytes first (:mod:`service.json_count`): a cloud of
    more than ``max_points`` is refused before any Python object is built for it.
    """
    rows, texty = scan_members(body)
    if max_points is not None:
        n = max(rows.get("points", 0), rows.get("normals", 0))
        if n > max_points:
            raise HTTPProblem("cloud-too-large", f"the cloud has {n} points; this service "
                              f"accepts at most {max_points} (CURVATURE_MAX_POINTS)")
    doc = parse_json(body, "malformed-request", "the body")
    if not isinstance(doc, dict):
        raise HTTPProblem("invalid-request", "the body must be a JSON object with 'points'")
    unknown = sorted(set(doc) - _JSON_KEYS)
    if unknown:
        raise HTTPProblem("invalid-request", f"unknown member(s) {unknown}; accepted: "
                          f"{sorted(_JSON_KEYS)}")
    if "points" not in doc:
        raise HTTPProblem("invalid-request", "missing member 'points'")
    for name in ("points", "normals", "faces"):
        if name in texty and doc.get(name) is not None:
            raise HTTPProblem("invalid-cloud", f"{name}: expected numbers (or null), found "
                              "true, false or a string")
    params = parse_params(doc.get("params"))
    # JSON null becomes NaN here, so it is reported as a non-finite coordinate.
    points = _as_array(doc["points"], "points", np.float64)
    normals = None if doc.get("normals") is None else _as_array(doc["normals"], "normals",
                                                                np.float64)
    if params.get("orientation") == "normals" and normals is None:  # as the schema says
        raise HTTPProblem("invalid-parameters", "orientation 'normals' needs per-point "
                          "normals: send 'normals' with the points")
    if normals is not None and not np.isfinite(normals).all():  # null, as the schema says
        row = int(np.flatnonzero(~np.isfinite(normals).all(axis=1))[0])
        raise HTTPProblem("invalid-cloud", f"normals: row {row} is not three finite numbers")
    faces = None
    if doc.get("faces") is not None and not isinstance(doc["faces"], list):
        raise HTTPProblem("invalid-cloud", "faces: expected a list of [i, j, k] index triples")
    if doc.get("faces"):
        faces = _as_array(doc["faces"], "faces", np.float64)
        if not np.all(np.isfinite(faces)) or not np.all(faces == np.round(faces)):
            raise HTTPProblem("invalid-cloud", "faces: vertex indices must be whole numbers")
        # Clipped first so huge values cast cleanly; they stay out of range and are named
        # by the range check below.
        faces = np.clip(faces, -1, np.iinfo(np.int64).max // 2).astype(np.int64)
    try:
        check_cloud(CloudInput(points=points, normals=normals, faces=faces))
    except ProblemError as exc:
        raise HTTPProblem(exc.slug, exc.detail) from None
    if faces is not None and ((faces < 0) | (faces >= len(points))).any():
        row = int(np.flatnonzero(((faces < 0) | (faces >= len(points))).any(axis=1))[0])
        raise HTTPProblem("invalid-cloud", f"faces: row {row} refers to a vertex outside "
                          f"0..{len(points) - 1}")
    arrays = {"points": points}
    if normals is not None:
        arrays["normals"] = normals
    if faces is not None:
        arrays["faces"] = faces
    with open(folder / "input.npz", "wb") as fh:
        np.savez(fh, **arrays)
    return params, len(points)


async def _receive_json(request: Request, folder: Path, settings: Settings) -> ReceivedInput:
    body = await _read_limited(request, settings)
    params, n = await anyio.to_thread.run_sync(_decode_cloud, body, folder,
                                               settings.max_points)
    return ReceivedInput(kind="arrays", input_file="input.npz", filename=None, format="json",
                         size=len(body), params=params, n_points=n)
