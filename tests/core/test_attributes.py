"""Input attributes, the input index and the file's viewpoint reach every result format."""

from __future__ import annotations

import json

import numpy as np
import pytest

import curvature
from curvature.cloud import PointCloud
from curvature.io import read_bytes, read_result

FORMATS = ("ply", "csv", "npz", "json")


def organized_pcd(width=12, height=10, holes=(3, 17, 50, 51, 119)) -> tuple[bytes, np.ndarray]:
    """A binary organized PCD of a bumpy sheet with packed rgba colours and NaN holes."""
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    pts = np.stack([u.ravel() * 0.1, v.ravel() * 0.1, 0.02 * np.sin(u.ravel())], axis=1)
    pts[list(holes)] = np.nan
    rgba = (np.arange(width * height, dtype=np.uint32) * 2654435761) & 0xFFFFFFFF
    rec = np.empty(width * height, dtype=[("xyz", "<f4", 3), ("rgba", "<u4"), ("i", "<f4")])
    rec["xyz"], rec["rgba"], rec["i"] = pts, rgba, np.arange(width * height) / 7.0
    head = ("VERSION 0.7\nFIELDS x y z rgba intensity\nSIZE 4 4 4 4 4\nTYPE F F F U F\n"
            f"COUNT 1 1 1 1 1\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0.5 0.4 3 1 0 0 0\n"
            f"POINTS {width * height}\nDATA binary\n")
    return head.encode() + rec.tobytes(), rgba


def test_organized_pcd_keeps_grid_index_colours_and_viewpoint(tmp_path):
    data, rgba = organized_pcd()
    cloud = read_bytes(data, "pcd")
    kept = np.setdiff1d(np.arange(120), [3, 17, 50, 51, 119])
    np.testing.assert_array_equal(cloud.index, kept)
    assert cloud.grid == (12, 10) and cloud.dropped == 5
    np.testing.assert_array_equal(cloud.viewpoint, [0.5, 0.4, 3.0])
    res = curvature.estimate(cloud, "knn", k=10, workers=1)
    assert res.info["orientation_rule"] == "viewpoint from the file (PCD VIEWPOINT)"
    assert res.info["grid"] == {"width": 12, "height": 10}
    np.testing.assert_array_equal(res.index, kept)
    np.testing.assert_array_equal(res.attributes["row"], kept // 12)
    np.testing.assert_array_equal(res.attributes["col"], kept % 12)
    ok = res.status == 0
    to_view = np.array([0.5, 0.4, 3.0]) - res.points
    assert np.all(np.einsum("ij,ij->i", res.normals[ok], to_view[ok]) > 0)
    for fmt in FORMATS:
        path = tmp_path / f"res.{fmt}"
        curvature.write(path, res)
        if fmt == "json":
            fields = json.loads(path.read_text())["fields"]
            got = {k: np.asarray(fields[k]) for k in ("index", "row", "red", "alpha")}
        else:
            got = read_result(path).attributes
        np.testing.assert_array_equal(got["index"], kept)
        np.testing.assert_array_equal(got["row"], kept // 12)
        # packed colours come back as the same bytes, channel by channel
        np.testing.assert_array_equal(got["red"], (rgba[kept] >> 16) & 0xFF)
        np.testing.assert_array_equal(got["alpha"], rgba[kept] >> 24)


@pytest.mark.parametrize("fmt", FORMATS)
def test_colours_and_user_fields_come_back_unchanged(tmp_path, fmt):
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(80, 3))
    props = {"red": rng.integers(0, 256, 80).astype(np.uint8),
             "green": rng.integers(0, 256, 80).astype(np.uint8),
             "blue": rng.integers(0, 256, 80).astype(np.uint8),
             "intensity": rng.random(80).astype(np.float32),
             "confidence": rng.integers(-5, 5, 80).astype(np.int16),
             "k1": np.arange(80.0)}  # clashes with a result field: kept as input_k1
    res = curvature.estimate(PointCloud(points=pts, properties=props), "knn", k=10, workers=1)
    path = tmp_path / f"res.{fmt}"
    curvature.write(path, res)
    if fmt == "json":
        fields = json.loads(path.read_text())["fields"]
        got = {k: np.asarray(v) for k, v in fields.items()}
    else:
        got = read_result(path).attributes
    for name, values in props.items():
        key = "input_k1" if name == "k1" else name
        # text formats hold the shortest decimal that reads back as the same value
        np.testing.assert_array_equal(got[key].astype(values.dtype), values)
        if fmt in ("ply", "npz"):  # typed formats keep the type too
            assert got[key].dtype == values.dtype
    np.testing.assert_array_equal(got["index"], np.arange(80))


def test_shape_index_and_curvedness():
    res = curvature.estimate(_sphere(2000, 2.0), "knn", k=16, fit="monge", workers=1)
    ok = res.status == 0
    # outward normals on a sphere: a convex cap everywhere, S = +1, C = 1/r
    np.testing.assert_allclose(res.shape_index[ok], 1.0, atol=0.05)
    np.testing.assert_allclose(res.curvedness[ok], 0.5, rtol=0.05)
    res.k1[:3], res.k2[:3] = [1.0, 1.0, 0.0], [-1.0, 0.0, 0.0]
    np.testing.assert_allclose(res.shape_index[:2], [0.0, 0.5])  # saddle, ridge
    assert np.isnan(res.shape_index[2])  # planar: no shape


def _sphere(n, r):
    rng = np.random.default_rng(1)
    p = rng.normal(size=(n, 3))
    return r * p / np.linalg.norm(p, axis=1)[:, None]


def test_ply_viewpoint_comment_orients_normals(tmp_path):
    pts = _sphere(500, 1.0)
    path = tmp_path / "scan.ply"
    head = ("ply\nformat ascii 1.0\ncomment viewpoint 0.1 0.2 0.3\nelement vertex 500\n"
            "property double x\nproperty double y\nproperty double z\nend_header\n")
    path.write_text(head + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in pts.tolist()))
    cloud = curvature.read(path)
    np.testing.assert_array_equal(cloud.viewpoint, [0.1, 0.2, 0.3])
    res = curvature.estimate(cloud, "knn", k=12, workers=1)
    assert res.info["orientation_rule"] == "viewpoint from the file (PLY viewpoint comment)"
    ok = res.status == 0
    assert np.mean(res.mean[ok] < 0) > 0.99  # viewer inside: normals point in
    # an explicit orientation still wins over the file
    res = curvature.estimate(cloud, "knn", k=12, workers=1, orientation="auto")
    assert res.info["orientation_rule"].startswith("auto")
    assert np.mean(res.mean[res.status == 0] > 0) > 0.99
    curvature.write(tmp_path / "r.ply", curvature.estimate(cloud, "knn", k=12, workers=1))
    assert b"comment viewpoint 0.1 0.2 0.3" in (tmp_path / "r.ply").read_bytes()[:2000]
