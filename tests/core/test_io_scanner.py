"""LAS/LAZ and E57: readers keep every field, writers give it back, errors name the place."""

from __future__ import annotations

import numpy as np
import pytest

import curvature
from curvature.errors import FormatError
from curvature.io import read_bytes, read_result, write_bytes

pytest.importorskip("laspy", reason="LAS/LAZ need the 'formats' extra (laspy, lazrs)")
pytest.importorskip("lazrs", reason="LAZ needs the 'formats' extra (lazrs)")

from scanner_files import N, e57_file, las_bytes, sphere  # noqa: E402


@pytest.mark.parametrize("version,point_format,compress", [
    ("1.2", 3, False), ("1.2", 3, True), ("1.3", 1, False), ("1.4", 7, True), ("1.4", 6, False),
])
def test_las_versions_read_points_and_every_dimension(version, point_format, compress):
    cloud = read_bytes(las_bytes(version, point_format, compress), "laz" if compress else "las")
    np.testing.assert_allclose(cloud.points, sphere() * 10.0 + 100.0, atol=1e-4)
    assert np.array_equal(cloud.properties["intensity"], np.arange(N) * 100)
    assert np.array_equal(cloud.properties["classification"], np.arange(N) % 5)
    np.testing.assert_array_equal(cloud.properties["reflectance"],
                                  np.linspace(0, 1, N).astype(np.float32))
    if point_format in (3, 7):
        assert np.array_equal(cloud.properties["red"], np.arange(N) * 1000)


def test_las_errors_name_file_and_place():
    good = las_bytes()
    with pytest.raises(FormatError, match="'LASF'") as err:
        read_bytes(b"LASX" + good[4:], "las", source="scan.las")
    assert "scan.las" in str(err.value) and err.value.offset == 0
    with pytest.raises(FormatError, match="only .* bytes follow") as err:
        read_bytes(good[:-100], "las", source="scan.las")
    assert err.value.offset == len(good) - 100
    with pytest.raises(FormatError, match="header needs"):
        read_bytes(good[:100], "las")


@pytest.mark.parametrize("fmt", ["las", "laz"])
def test_result_as_las_keeps_curvature_and_attributes(tmp_path, fmt):
    cloud = read_bytes(las_bytes(compress=True), "laz")
    res = curvature.estimate(cloud, "knn", k=10, workers=1)
    path = tmp_path / f"res.{fmt}"
    curvature.write(path, res)
    back = read_result(path)
    np.testing.assert_allclose(back.points, res.points, atol=1e-6)
    for name in ("k1", "k2", "mean", "gaussian", "residual"):
        np.testing.assert_array_equal(getattr(back, name), getattr(res, name))
    np.testing.assert_array_equal(back.normals, res.normals)
    np.testing.assert_array_equal(back.status, res.status)
    np.testing.assert_array_equal(back.index, np.arange(N))
    # the input's standard dimensions go back into LAS's own fields, unchanged
    for name in ("intensity", "classification", "red", "green", "blue", "reflectance"):
        np.testing.assert_array_equal(back.attributes[name], cloud.properties[name])


def test_e57_several_scans_with_poses_and_invalid_points(tmp_path):
    pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
    path = tmp_path / "two.e57"
    expected = e57_file(path, scans=((0, 0, 0), (5.0, -1.0, 2.0)), invalid_every=7)
    cloud = curvature.read(path)
    np.testing.assert_allclose(cloud.points, np.concatenate(expected), atol=1e-5)
    valid = np.flatnonzero(np.arange(N) % 7 != 0)
    np.testing.assert_array_equal(cloud.index, np.concatenate([valid, valid + N]))
    assert cloud.dropped == 2 * (N - valid.size)
    assert np.array_equal(cloud.properties["scan"], np.repeat([0, 1], valid.size))
    assert np.array_equal(cloud.properties["red"], np.concatenate([valid % 256] * 2))
    assert np.array_equal(cloud.properties["green"], np.repeat([0, 1], valid.size))
    # two scans: each point's viewpoint is its own scan's origin
    np.testing.assert_array_equal(cloud.viewpoint, np.repeat([[0, 0, 0], [5.0, -1.0, 2.0]],
                                                             valid.size, axis=0))


def test_e57_two_scans_each_point_faces_its_own_scanner(tmp_path):
    pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
    path = tmp_path / "two_poses.e57"
    origins = np.array([[0.0, 0.0, 0.0], [4.0, 1.0, -0.5]])
    turn = (np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4))  # 90 degrees about z
    expected = e57_file(path, scans=origins, n=400, rotations=[(1.0, 0, 0, 0), turn])
    cloud = curvature.read(path)
    np.testing.assert_allclose(cloud.points, np.concatenate(expected), atol=1e-5)
    res = curvature.estimate(cloud, "knn", k=16, workers=1)
    assert res.info["orientation"] == "viewpoint"
    assert res.info["orientation_rule"] == ("viewpoint from the file (E57 scan poses: each "
                                            "point faces its own scan's origin, 2 scans)")
    assert "viewpoint" not in res.info  # no single position to report
    scan = res.attributes["scan"]
    own = origins[scan] - res.points
    facing = np.einsum("ij,ij->i", res.normals, own) > 0
    ok = res.status == 0
    assert facing[ok].all()
    # each sphere is seen from its centre: normals point inwards, so H < 0 on both scans
    for s in (0, 1):
        assert np.mean(res.mean[ok & (scan == s)] < 0) > 0.99
    # one viewpoint for the whole file (the first scan's) would turn about half of the
    # second scan's normals the wrong way: the per-scan rule is what makes them right
    single = curvature.estimate(cloud, "knn", k=16, workers=1, viewpoint=origins[0])
    wrong = np.einsum("ij,ij->i", single.normals, own) < 0
    assert 0.3 < wrong[ok & (scan == 1)].mean() < 0.7


def test_e57_single_scan_pose_orients_normals_and_goes_to_las_and_ply(tmp_path):
    pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
    path = tmp_path / "one.e57"
    # scanner inside the sphere: normals facing it point inwards, so H < 0
    e57_file(path, scans=((3.0, 1.0, -2.0),), n=400)
    cloud = curvature.read(path)
    np.testing.assert_allclose(cloud.viewpoint, [3.0, 1.0, -2.0])
    res = curvature.estimate(cloud, "knn", k=16, workers=1)
    assert res.info["orientation"] == "viewpoint"
    assert res.info["orientation_rule"] == "viewpoint from the file (E57 scan pose)"
    ok = res.status == 0
    assert np.mean(res.mean[ok] < 0) > 0.99
    for fmt in ("las", "ply"):
        curvature.write(tmp_path / f"r.{fmt}", res)
        back = read_result(tmp_path / f"r.{fmt}")
        for name in ("intensity", "scan", "index"):
            np.testing.assert_array_equal(back.attributes[name], res.attributes[name])
        # LAS colours are 16-bit: 8-bit channels come back scaled by 257 (255 -> 65535)
        scale = 257 if fmt == "las" else 1
        for name in ("red", "green", "blue"):
            np.testing.assert_array_equal(back.attributes[name],
                                          res.attributes[name].astype(np.int64) * scale)
        np.testing.assert_array_equal(back.k1, res.k1)
        np.testing.assert_array_equal(back.status, res.status)


def test_e57_errors():
    pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
    with pytest.raises(FormatError, match="ASTM-E57") as err:
        read_bytes(b"not an e57 file at all" * 4, "e57", source="x.e57")
    assert err.value.offset == 0
    header = b"ASTM-E57" + np.array([1, 0], "<u4").tobytes() + np.array(
        [4096, 1024, 100, 1024], "<u8").tobytes()
    with pytest.raises(FormatError, match="says the file has 4096 bytes") as err:
        read_bytes(header + b"\0" * 100, "e57")
    assert err.value.offset == 16


def test_unknown_extension_lists_the_new_formats():
    with pytest.raises(curvature.UnknownFormatError, match="e57.*las.*laz"):
        curvature.io.format_from_path("scan.rcp")
    assert write_bytes(sphere(20), "laz")[:4] == b"LASF"
