"""Property-based fuzzing of the service's own readers: the JSON cloud body and multipart
uploads. Whatever arrives, the answer is a 4xx problem (or a valid cloud), never a 500, and
reading it takes bounded memory."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from service_helpers import sphere

from service.problems import HTTPProblem
from service.uploads import _decode_cloud

FUZZ = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
VALID = {"points": sphere(12).round(4).tolist(), "params": {"method": "knn", "k": 5}}
HUGE_NUMBERS = ["1e999", "-1e999", "1" + "0" * 400, "9" * 5000, "-0", "1e-999",
                "18446744073709551616", "NaN", "Infinity"]


def nested(depth: int, open_: str = "[", close: str = "]") -> str:
    return open_ * depth + "1" + close * depth


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True)
    | st.text(max_size=5),
    lambda children: st.lists(children, max_size=5)
    | st.dictionaries(st.sampled_from(["points", "normals", "faces", "params", "method", "k",
                                       "fit", "x"]), children, max_size=4),
    max_leaves=40)


@st.composite
def cloud_documents(draw) -> bytes:
    """Mostly well-formed bodies with one member replaced, or damaged text of a valid one."""
    kind = draw(st.sampled_from(["member", "bytes", "nesting", "number"]))
    doc = json.dumps(VALID)
    if kind == "member":
        member = draw(st.sampled_from(["points", "normals", "faces", "params", "other"]))
        changed = dict(VALID)
        changed[member] = draw(json_values)
        return json.dumps(changed).encode()
    if kind == "nesting":
        depth = draw(st.sampled_from([50, 1000, 5000, 100_000]))
        where = draw(st.sampled_from(["points", "params", "top"]))
        deep = nested(depth, *draw(st.sampled_from([("[", "]"), ('{"a":', "}")])))
        if where == "top":
            return deep.encode()
        return doc.replace(json.dumps(VALID[where]) if where in VALID else "", deep, 1).encode()
    if kind == "number":
        number = draw(st.sampled_from(HUGE_NUMBERS))
        target = draw(st.sampled_from(["0.", "5}", "[0"]))
        return doc.replace(target, target[0] + number + target[1:], 1).encode()
    data = bytearray(doc.encode())
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(data) - 1))
        op = draw(st.sampled_from(["cut", "flip", "insert"]))
        if op == "cut":
            del data[at:]
            if not data:
                data = bytearray(b"{")
        elif op == "flip":
            data[at] = draw(st.integers(0, 255))
        else:
            data[at:at] = draw(st.sampled_from([b"[", b"{", b'"', b",", b"\xff", b"null"]))
    return bytes(data)


def decode(body: bytes, tmp_path):
    for leftover in tmp_path.iterdir():
        leftover.unlink()
    return _decode_cloud(body, tmp_path)


@FUZZ
@given(body=cloud_documents())
def test_json_bodies_give_a_cloud_or_a_4xx_problem(tmp_path_factory, body):
    folder = tmp_path_factory.mktemp("fuzz", numbered=True)
    tracemalloc.start()
    try:
        params, n = decode(body, folder)
    except HTTPProblem as exc:
        assert 400 <= exc.kind.status < 500, exc
        assert exc.detail
        params = None
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < 4_000_000 + 40 * len(body), f"{peak} bytes for a {len(body)}-byte body"
    if params is not None:
        with np.load(folder / "input.npz") as data:
            assert data["points"].shape == (n, 3) and np.isfinite(data["points"]).all()


@pytest.mark.parametrize(("body", "slug"), [
    (nested(100_000).encode(), "malformed-request"),
    (('{"points": ' + nested(3000) + "}").encode(), "malformed-request"),
    (('{"points": [[1' + "0" * 5000 + ", 2, 3]]}").encode(), "malformed-request"),
    (('{"points": [[1' + "0" * 400 + ", 2, 3]]}").encode(), "invalid-cloud"),
    (b'{"points": [[1e999, 2, 3]]}', "too-few-points"),
    (('{"points": ' + json.dumps(VALID["points"]).replace("0.", "1e999", 1) + "}").encode(),
     "non-finite-coordinates"),
    (('{"points": ' + json.dumps(VALID["points"]) + ', "faces": 7}').encode(), "invalid-cloud"),
    (('{"points": ' + json.dumps(VALID["points"]) + ', "faces": [[0, 1, 1e300]]}').encode(),
     "invalid-cloud"),
    (('{"points": ' + json.dumps(VALID["points"]) + ', "params": ' + nested(2000, '{"a":', "}")
      + "}").encode(), "malformed-request"),
])
def test_adversarial_json_bodies(tmp_path, body, slug):
    with pytest.raises(HTTPProblem) as info:
        decode(body, tmp_path)
    assert info.value.slug == slug, info.value


@st.composite
def multipart_bodies(draw) -> bytes:
    """A valid upload (12-point XYZ file + params), then truncated, flipped or spliced."""
    xyz = "".join(f"{x} {y} {z}\n" for x, y, z in sphere(12).round(4).tolist()).encode()
    data = bytearray(b'--zz\r\nContent-Disposition: form-data; name="file"; filename="a.xyz"'
                     b"\r\n\r\n" + xyz + b'\r\n--zz\r\nContent-Disposition: form-data; '
                     b'name="params"\r\n\r\n{"method": "knn", "k": 5}\r\n--zz--\r\n')
    for _ in range(draw(st.integers(1, 3))):
        if not data:
            break
        at = draw(st.integers(0, len(data) - 1))
        op = draw(st.sampled_from(["cut", "flip", "splice"]))
        if op == "cut":
            del data[at:]
        elif op == "flip":
            data[at] = draw(st.integers(0, 255))
        else:
            data[at:at] = draw(st.sampled_from([
                b"\r\n", b"--zz\r\n", b"--zz--", b'filename="x.ply"', b'name="file"',
                b"9" * 400, b"[" * 2000, b"\x00", b"Content-Type: x\r\n"]))
    return bytes(data)


@settings(max_examples=80, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(body=multipart_bodies())
def test_multipart_uploads_never_answer_500(client, body):
    response = client.post("/v1/curvature", content=body,
                           headers={"Content-Type": "multipart/form-data; boundary=zz"})
    assert response.status_code < 500 or response.status_code == 503, response.text
    if response.status_code >= 400:
        assert response.headers["content-type"] == "application/problem+json"
    assert not any(client.app.state.settings.tmp_dir.iterdir())  # scratch always removed
