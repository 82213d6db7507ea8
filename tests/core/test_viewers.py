"""Result PLY files as CloudCompare and MeshLab read them (the real programs, when present).

CloudCompare (Debian's package, command-line mode under xvfb-run) must load every result and
attribute column as a named scalar field; MeshLab (pymeshlab) must load the per-vertex
normals, colours and its one per-vertex scalar, ``quality`` (our mean curvature).
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

import curvature
from curvature.cloud import PointCloud

N = 300


@pytest.fixture(scope="module")
def result_ply(tmp_path_factory):
    rng = np.random.default_rng(5)
    p = rng.normal(size=(N, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    colours = {c: rng.integers(0, 256, N).astype(np.uint8) for c in ("red", "green", "blue")}
    cloud = PointCloud(points=p, properties={**colours, "reflectance": rng.random(N)})
    res = curvature.estimate(cloud, "knn", k=12, workers=1)
    path = tmp_path_factory.mktemp("viewers") / "result.ply"
    curvature.write(path, res)
    return path, res


def test_cloudcompare_loads_every_field_by_name(result_ply, tmp_path):
    if shutil.which("CloudCompare") is None or shutil.which("xvfb-run") is None:
        pytest.skip("CloudCompare and xvfb-run are not installed (.ci/run installs them)")
    path, res = result_ply
    out = tmp_path / "export.asc"
    run = subprocess.run(["xvfb-run", "-a", "CloudCompare", "-SILENT", "-AUTO_SAVE", "OFF",
                          "-O", str(path), "-C_EXPORT_FMT", "ASC", "-ADD_HEADER",
                          "-SAVE_CLOUDS", "FILE", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    lines = out.read_text().splitlines()
    names = lines[0].lstrip("/").split()
    for name in ("k1", "k2", "mean", "gaussian", "status", "residual", "neighbor_count",
                 "shape_index", "curvedness", "index", "reflectance", "d1x", "d2z"):
        assert name in names, names
    table = np.loadtxt(lines[1:])
    assert table.shape == (N, len(names))
    col = {name: table[:, j] for j, name in enumerate(names)}
    ok = res.status == 0
    # CloudCompare keeps scalar fields in single precision
    np.testing.assert_allclose(col["k1"][ok], res.k1[ok], rtol=1e-5)
    np.testing.assert_array_equal(col["status"], res.status)
    np.testing.assert_array_equal(col["index"], np.arange(N))
    for ours, theirs in (("red", "R"), ("green", "G"), ("blue", "B")):
        np.testing.assert_array_equal(col[theirs], res.attributes[ours])
    np.testing.assert_allclose(np.stack([col["Nx"], col["Ny"], col["Nz"]], 1)[ok],
                               res.normals[ok], atol=3e-3)  # CloudCompare quantizes normals


def test_meshlab_reads_normals_colours_and_quality(result_ply):
    pymeshlab = pytest.importorskip("pymeshlab", reason="pymeshlab is in the 'viewers' extra")
    path, res = result_ply
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    mesh = ms.current_mesh()
    assert mesh.vertex_number() == N
    ok = res.status == 0
    np.testing.assert_allclose(mesh.vertex_normal_matrix()[ok], res.normals[ok], atol=1e-5)
    colours = mesh.vertex_color_matrix()  # RGBA in 0..1
    np.testing.assert_allclose(colours[:, 0] * 255, res.attributes["red"], atol=0.5)
    assert mesh.has_vertex_scalar()
    np.testing.assert_allclose(mesh.vertex_scalar_array()[ok], res.mean[ok], rtol=1e-5)
