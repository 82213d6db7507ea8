"""Mesh formats: GLB/glTF and 3MF through trimesh, OBJ/STL/OFF (our readers) against trimesh.

Files are written by trimesh itself, so each reader is checked against an independent writer;
the error tests build files that lie about their sizes, and every trimesh exception must come
back as a FormatError naming the file.
"""

from __future__ import annotations

import io
import json
import struct
import zipfile

import numpy as np
import pytest

import curvature
from curvature.errors import FormatError
from curvature.io import read_bytes

trimesh = pytest.importorskip("trimesh", reason="trimesh is a core dependency")

SHIFT = np.array([5.0, -1.0, 2.0])


def sphere_mesh(colour=None):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    if colour is not None:
        mesh.visual.vertex_colors = np.tile(np.asarray(colour, np.uint8), (len(mesh.vertices), 1))
    return mesh


def two_mesh_scene():
    """A sphere moved by SHIFT (red) and a box at the origin (blue), as one scene."""
    scene = trimesh.Scene()
    scene.add_geometry(sphere_mesh((200, 10, 20, 255)), node_name="ball",
                       transform=trimesh.transformations.translation_matrix(SHIFT))
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    box.visual.vertex_colors = np.tile(np.array([0, 0, 255, 255], np.uint8), (8, 1))
    scene.add_geometry(box, node_name="box")
    return scene


def triangles(points, faces):
    """Each face as its sorted corner coordinates, rows sorted: comparable across orders."""
    tri = np.sort(np.round(points[faces], 6).reshape(len(faces), -1), axis=1)
    return tri[np.lexsort(tri.T[::-1])]


def assert_same_mesh(cloud, mesh):
    np.testing.assert_allclose(np.unique(np.round(cloud.points, 6), axis=0),
                               np.unique(np.round(mesh.vertices, 6), axis=0))
    np.testing.assert_allclose(triangles(cloud.points, cloud.faces),
                               triangles(np.asarray(mesh.vertices), np.asarray(mesh.faces)))


# --- OBJ, STL, OFF: our readers on trimesh's files --------------------------------------

@pytest.mark.parametrize("fmt,file_type", [("obj", "obj"), ("stl", "stl"),
                                           ("stl", "stl_ascii"), ("off", "off")])
def test_our_mesh_readers_agree_with_trimesh(fmt, file_type):
    mesh = sphere_mesh()
    data = mesh.export(file_type=file_type)
    cloud = read_bytes(data if isinstance(data, bytes) else data.encode(), fmt)
    assert len(cloud) == len(mesh.vertices)
    assert_same_mesh(cloud, mesh)


# --- GLB, glTF, 3MF through trimesh ---------------------------------------------------------

def test_glb_scene_every_mesh_transformed_with_colours(tmp_path):
    path = tmp_path / "scene.glb"
    path.write_bytes(two_mesh_scene().export(file_type="glb"))
    cloud = curvature.read(path)
    ball = sphere_mesh()
    assert len(cloud) == len(ball.vertices) + 8
    is_ball = np.linalg.norm(cloud.points - SHIFT, axis=1) < 1.0 + 1e-6
    np.testing.assert_allclose(np.linalg.norm(cloud.points[is_ball] - SHIFT, axis=1), 1.0,
                               atol=1e-6)
    assert is_ball.sum() == len(ball.vertices)
    np.testing.assert_allclose(np.abs(cloud.points[~is_ball]), [[0.5, 1.0, 1.5]] * 8)
    assert cloud.faces.shape == (len(ball.faces) + 12, 3)
    assert np.array_equal(cloud.properties["red"], np.where(is_ball, 200, 0))
    assert np.array_equal(cloud.properties["blue"], np.where(is_ball, 20, 255))
    res = curvature.estimate(cloud, "mesh", workers=1)
    ok = (res.status == 0) & is_ball
    np.testing.assert_allclose(np.abs(res.k1[ok]), 1.0, rtol=0.05)
    assert np.array_equal(res.attributes["red"], cloud.properties["red"])


def test_gltf_with_embedded_buffers():
    from trimesh.exchange.gltf import export_gltf

    files = export_gltf(two_mesh_scene(), embed_buffers=True)
    (name, data), = files.items()
    assert name.endswith(".gltf")
    cloud = read_bytes(data, "gltf", source="scene.gltf")
    assert len(cloud) == len(sphere_mesh().vertices) + 8


def test_3mf_package():
    mesh = sphere_mesh()
    cloud = read_bytes(mesh.export(file_type="3mf"), "3mf", source="part.3mf")
    assert_same_mesh(cloud, mesh)


# --- sizes checked before trimesh, its errors wrapped ----------------------------------------

def glb_parts(data: bytes):
    """The JSON document and binary chunk of a GLB."""
    json_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + json_len])
    bin_len = struct.unpack_from("<I", data, 20 + json_len)[0]
    return doc, data[28 + json_len:28 + json_len + bin_len]


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + \
        struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def test_glb_header_and_size_errors_name_file_and_place():
    good = sphere_mesh().export(file_type="glb")
    assert len(read_bytes(glb_bytes(*glb_parts(good)), "glb")) == 162  # the rebuild is valid
    with pytest.raises(FormatError, match="'glTF'") as err:
        read_bytes(b"glTX" + good[4:], "glb", source="m.glb")
    assert "m.glb" in str(err.value) and err.value.offset == 0
    with pytest.raises(FormatError, match="truncated or padded") as err:
        read_bytes(good[:-8], "glb", source="m.glb")
    assert err.value.offset == 8
    doc, blob = glb_parts(good)
    doc["accessors"][1]["count"] = 10**9  # a lying vertex count
    with pytest.raises(FormatError, match=r"accessor 1 needs .* bytes \(1000000000 items\)"):
        read_bytes(glb_bytes(doc, blob), "glb", source="m.glb")
    doc, blob = glb_parts(good)
    doc["buffers"][0]["byteLength"] = len(blob) + 4096
    with pytest.raises(FormatError, match="buffer 0 claims"):
        read_bytes(glb_bytes(doc, blob), "glb")
    doc, blob = glb_parts(good)
    doc["buffers"][0]["uri"] = "../secret.bin"
    with pytest.raises(FormatError, match="external file '../secret.bin'"):
        read_bytes(glb_bytes(doc, blob), "glb")


def test_instancing_bomb_and_cycles_are_refused():
    doc, blob = glb_parts(sphere_mesh().export(file_type="glb"))
    # 20,000 nodes each instancing the whole mesh: 20,000 times the output of one copy
    doc["nodes"] = [{"mesh": 0}] * 20000
    doc["scenes"] = [{"nodes": list(range(20000))}]
    with pytest.raises(FormatError, match="instances .* rows from a"):
        read_bytes(glb_bytes(doc, blob), "glb", source="bomb.glb")
    doc["nodes"] = [{"children": [1]}, {"children": [0], "mesh": 0}]
    doc["scenes"] = [{"nodes": [0]}]
    with pytest.raises(FormatError, match="cycle"):
        read_bytes(glb_bytes(doc, blob), "glb")


def test_trimesh_exceptions_become_format_errors():
    doc, blob = glb_parts(sphere_mesh().export(file_type="glb"))
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 99  # no such accessor
    with pytest.raises(FormatError, match="could not read as glb") as err:
        read_bytes(glb_bytes(doc, blob), "glb", source="broken.glb")
    assert "broken.glb" in str(err.value)
    with pytest.raises(FormatError, match="does not parse"):
        read_bytes(b"{not json", "gltf", source="x.gltf")


def test_3mf_errors_zip_bomb_and_not_a_zip():
    with pytest.raises(FormatError, match="zip archive") as err:
        read_bytes(b"PK but not really a zip" * 4, "3mf", source="p.3mf")
    assert "p.3mf" in str(err.value)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("3D/3dmodel.model", b" " * (64 << 20))  # 64 MiB of blanks, deflates to KiB
    with pytest.raises(FormatError, match="inflate to 67,108,864 bytes"):
        read_bytes(buffer.getvalue(), "3mf", source="bomb.3mf")
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as z:
        z.writestr("3D/3dmodel.model", b"<model><resources><object id='1'>")
    with pytest.raises(FormatError, match="3dmodel.model"):
        read_bytes(buffer.getvalue(), "3mf")


# --- fuzzing: a corrupted file is a FormatError, nothing else -------------------------------

@pytest.mark.parametrize("fmt", ["glb", "3mf"])
def test_corrupted_mesh_files_raise_only_format_errors(fmt):
    from hypothesis import HealthCheck, given, settings
    from test_io_fuzz import corruptions

    seed = two_mesh_scene().export(file_type=fmt)
    assert len(read_bytes(seed, fmt)) >= 10

    @settings(max_examples=40, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(corruptions(seed))
    def check(data):
        try:
            cloud = read_bytes(data, fmt)
        except FormatError:
            return
        assert cloud.points.shape[1] == 3 and len(cloud) >= 10

    check()
