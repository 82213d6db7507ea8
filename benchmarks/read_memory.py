"""Memory per input byte of reading every input format the way a worker reads it.

Usage::

    python benchmarks/read_memory.py                    # 1,000,000 points, every format
    python benchmarks/read_memory.py --points 200000 --json /tmp/memory.json

For each format a cloud is written in two contents: ``typical`` (coordinates of a unit
normal cloud with 6 decimals, the way scanners export) and ``dense`` (one-digit integers:
the most values per byte a text file can hold, so the worst case of a text reader), with
and without faces for the mesh formats. Each file is then loaded in a fresh process by
``service.inputs.load_input`` plus the cloud checks (a JSON body by the server's
``_decode_cloud``), and two figures are divided by the file's size:

- ``traced``: the peak of Python's allocations during the load (``tracemalloc``; numpy's
  buffers are traced), including the file's bytes read into memory;
- ``rss``: in another fresh process without tracing (tracemalloc's own records would
  count for millions of small Python objects), the growth of the peak resident set
  (``VmHWM``, reset through ``/proc/self/clear_refs`` just before) over its size then
  (Linux only).

The largest of these over every format is the bound ``docs/reliability.md`` reports.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

_MEASURE = r"""
import json, sys, tracemalloc
from pathlib import Path
mode, kind, path = sys.argv[1], sys.argv[2], Path(sys.argv[3])
import numpy as np, curvature
from service import inputs, uploads
def status(key):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024
body = path.read_bytes() if kind == "json" else None  # a JSON body is in memory anyway
Path("/proc/self/clear_refs").write_text("5")  # the peak resident set starts again here
rss0 = status("VmRSS")
if mode == "traced":
    tracemalloc.start()
if kind == "json":
    uploads._decode_cloud(body, path.parent, max_points=100_000_000)
else:
    cloud = inputs.load_input(path, "file", path.name, 100_000_000)
    inputs.check_cloud(cloud)
if mode == "traced":
    print(json.dumps({"traced": tracemalloc.get_traced_memory()[1]}))
else:
    print(json.dumps({"rss": status("VmHWM") - rss0}))
"""


def _text_rows(values: np.ndarray, fmt: str) -> str:
    """Rows of numbers as text: ``%.6f`` for typical content, ``%d`` for dense."""
    buffer = []
    for lo in range(0, len(values), 100_000):
        chunk = values[lo:lo + 100_000]
        spec = " ".join([fmt] * chunk.shape[1])
        buffer.append("\n".join(spec % tuple(row) for row in chunk.tolist()))
    return "\n".join(buffer) + "\n"


def _faces(n: int) -> np.ndarray:
    i = np.arange(n - 2)
    return np.stack([i, i + 1, i + 2], axis=1)


def write_files(folder: Path, n: int, content: str) -> dict[str, Path]:
    """Every readable format of one cloud of ``n`` points, ``typical`` or ``dense``."""
    import curvature

    rng = np.random.default_rng(0)
    if content == "dense":
        points = rng.integers(0, 10, size=(n, 3)).astype(np.float64)
        fmt = "%d"
    else:
        points = rng.normal(size=(n, 3))
        fmt = "%.6f"
    rows = _text_rows(points, fmt)
    faces = _faces(n)
    face_rows = _text_rows(np.hstack([np.full((len(faces), 1), 3), faces]), "%d")
    out: dict[str, Path] = {}

    def put(name: str, text: str | bytes) -> None:
        path = folder / name
        if isinstance(text, str):
            text = text.encode()
        path.write_bytes(text)
        out[name] = path

    ply_head = ("ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\n"
                "property float y\nproperty float z\n{faces}end_header\n")
    put("ascii.ply", ply_head.format(n=n, faces="") + rows)
    put("faces-ascii.ply", ply_head.format(
        n=n, faces=f"element face {len(faces)}\nproperty list uchar int vertex_indices\n")
        + rows + face_rows)
    put("cloud.xyz", rows)
    put("cloud.csv", "x,y,z\n" + rows.replace(" ", ","))
    put("cloud.pcd", "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                     f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
                     f"DATA ascii\n{rows}")
    put("cloud.obj", "".join(f"v {line}\n" for line in rows.splitlines()))
    put("faces.obj", "".join(f"v {line}\n" for line in rows.splitlines())
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces.tolist()))
    put("cloud.off", f"OFF\n{n} 0 0\n{rows}")
    put("faces.off", f"OFF\n{n} {len(faces)} 0\n{rows}{face_rows}")
    corners = points[faces[: n // 3]].reshape(-1, 3, 3)
    stl = ["solid s\n"]
    for tri in corners.tolist():
        stl.append("facet normal 0 0 1\nouter loop\n"
                   + "".join(f"vertex {fmt % a} {fmt % b} {fmt % c}\n" for a, b, c in tri)
                   + "endloop\nendfacet\n")
    put("ascii.stl", "".join(stl) + "endsolid s\n")
    if content == "typical":  # binary formats do not depend on the digits
        for name in ("cloud.ply", "faces.ply", "cloud.las", "cloud.laz"):
            cloud = curvature.PointCloud(points=points,
                                         faces=faces if name == "faces.ply" else None)
            curvature.write(folder / name, cloud)
            out[name] = folder / name
        np.save(folder / "cloud.npy", points)
        out["cloud.npy"] = folder / "cloud.npy"
        np.savez_compressed(folder / "cloud.npz", points=points)
        out["cloud.npz"] = folder / "cloud.npz"
        record = np.zeros(n // 3, dtype=[("normal", "<f4", 3), ("v", "<f4", (3, 3)),
                                         ("attr", "<u2")])
        record["v"] = corners
        put("binary.stl", b"\0" * 80 + np.uint32(len(record)).tobytes() + record.tobytes())
    digits = ".6f" if content == "typical" else ".0f"
    body = "[" + ",".join(f"[{a:{digits}},{b:{digits}},{c:{digits}}]"
                          for a, b, c in points.tolist()) + "]"
    put("body.json", '{"points": ' + body + "}")
    return out


def measure(n: int, only: set[str] | None = None) -> list[dict]:
    """One row per (content, file): bytes, traced and RSS peaks per input byte."""
    rows = []
    for content in ("typical", "dense"):
        with tempfile.TemporaryDirectory(prefix="curvature-mem-") as tmp:
            for name, path in write_files(Path(tmp), n, content).items():
                if only and name not in only:
                    continue
                kind = "json" if name.endswith(".json") else "file"
                row = {"content": content, "file": name, "file_bytes": path.stat().st_size}
                for mode in ("traced", "rss"):  # apart: tracing inflates the resident set
                    out = subprocess.run([sys.executable, "-c", _MEASURE, mode, kind,
                                          str(path)], cwd=REPO, capture_output=True, text=True,
                                         timeout=900)
                    if out.returncode != 0:
                        row["error"] = out.stderr.strip()[-300:]
                        break
                    got = json.loads(out.stdout.strip().splitlines()[-1])[mode]
                    row[mode] = got
                    row[f"{mode}_per_byte"] = round(got / row["file_bytes"], 2)
                rows.append(row)
                print(_line(row), flush=True)
    return rows


def _line(row: dict) -> str:
    head = f"{row['content']:<8} {row['file']:<16} {row['file_bytes'] / 1e6:8.1f} MB"
    if "error" in row:
        return f"{head}  ERROR {row['error']}"
    return (f"{head}  traced {row['traced'] / 1e6:8.1f} MB = {row['traced_per_byte']:5.2f}/B"
            f"  rss +{row['rss'] / 1e6:8.1f} MB = {row['rss_per_byte']:5.2f}/B")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--json", type=Path, help="also write the rows here")
    parser.add_argument("--only", nargs="+", help="file names to measure (cloud.xyz ...)")
    args = parser.parse_args(argv)
    rows = measure(args.points, set(args.only or ()))
    ok = [r for r in rows if "error" not in r]
    for key in ("traced_per_byte", "rss_per_byte"):
        worst = max(ok, key=lambda r: r[key])
        print(f"worst {key}: {worst[key]} ({worst['content']} {worst['file']})")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n", encoding="utf-8")
    return 0 if len(ok) == len(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
