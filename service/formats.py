"""File formats the service accepts and the result formats it serves."""

from __future__ import annotations

# Input formats the library reads (DESIGN.md section 6), by file extension.
INPUT_EXTENSIONS = ("ply", "pcd", "xyz", "csv", "txt", "asc", "npy", "npz", "obj", "stl", "off",
                    "glb", "gltf", "3mf", "las", "laz", "e57")

# Result formats and the media type each is served with. PLY has no registered media type;
# application/x-ply is the de-facto one (model/ply, application/ply and
# application/octet-stream are accepted in Accept as aliases). NPZ is a zip of .npy arrays.
# LAS/LAZ carry the curvature fields as extra dimensions.
RESULT_MEDIA_TYPES = {
    "json": "application/json",
    "ply": "application/x-ply",
    "csv": "text/csv; charset=utf-8",
    "npz": "application/x-npz",
    "las": "application/vnd.las",      # IANA-registered for LAS; LAZ has its own
    "laz": "application/vnd.laszip",
}
RESULT_FORMATS = tuple(RESULT_MEDIA_TYPES)


def extension_of(filename: str | None) -> str | None:
    """Lower-case extension without the dot, or ``None`` (``"scan.PLY"`` -> ``"ply"``)."""
    if not filename or "." not in filename:
        return None
    return filename.rsplit(".", 1)[1].lower() or None
