"""Small LAS/LAZ/E57 files built by the tests (shared by the format and fuzz tests)."""

from __future__ import annotations

import io

import numpy as np

N = 60


def sphere(n=N, seed=0, radius=1.0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    return radius * p / np.linalg.norm(p, axis=1)[:, None]


def las_bytes(version="1.2", point_format=3, compress=False, n=N) -> bytes:
    """A LAS file with intensity, classification, colours and one extra dimension."""
    import laspy

    header = laspy.LasHeader(point_format=point_format, version=version)
    header.add_extra_dims([laspy.ExtraBytesParams(name="reflectance", type=np.float32)])
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    p = sphere(n) * 10.0 + 100.0
    las.x, las.y, las.z = p[:, 0], p[:, 1], p[:, 2]
    las.intensity = np.arange(n, dtype=np.uint16) * 100
    las.classification = (np.arange(n) % 5).astype(np.uint8)
    if "red" in las.point_format.dimension_names:
        las.red = np.arange(n, dtype=np.uint16) * 1000
        las.green = np.full(n, 7, np.uint16)
        las.blue = np.full(n, 65535, np.uint16)
    las.reflectance = np.linspace(0, 1, n).astype(np.float32)
    buffer = io.BytesIO()
    las.write(buffer, do_compress=compress)
    return buffer.getvalue()


def rotation_matrix(quaternion) -> np.ndarray:
    """The (3, 3) rotation of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(quaternion, dtype=np.float64)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def e57_file(path, scans=((0.0, 0.0, 0.0),), n=N, invalid_every=0, rotations=None):
    """An E57 file of unit spheres, one per scan pose translation, with intensity and colours.

    ``rotations`` gives each scan's pose rotation as a quaternion (w, x, y, z); identity by
    default. Each sphere is centred on its scanner, so its points lie around the scan origin.
    Returns the points in the file's frame of every scan, valid ones only.
    """
    import pye57

    e57 = pye57.E57(str(path), mode="w")
    out = []
    rotations = [(1.0, 0.0, 0.0, 0.0)] * len(scans) if rotations is None else rotations
    for s, (origin, quaternion) in enumerate(zip(scans, rotations, strict=True)):
        p = sphere(n, seed=s)
        invalid = np.zeros(n, np.int8)
        if invalid_every:
            invalid[::invalid_every] = 1
        data = {"cartesianX": p[:, 0], "cartesianY": p[:, 1], "cartesianZ": p[:, 2],
                "intensity": np.linspace(0, 1, n),
                "colorRed": (np.arange(n) % 256).astype(np.uint8),
                "colorGreen": np.full(n, s, np.uint8), "colorBlue": np.full(n, 200, np.uint8),
                "cartesianInvalidState": invalid}
        e57.write_scan_raw(data, rotation=np.asarray(quaternion, dtype=np.float64),
                           translation=np.asarray(origin, dtype=np.float64))
        out.append(p[invalid == 0] @ rotation_matrix(quaternion).T + np.asarray(origin))
    e57.close()
    return out
