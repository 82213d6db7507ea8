"""Fuzzing the LAS/LAZ and E57 readers: a corrupted file is a FormatError, nothing else."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from curvature.errors import FormatError
from curvature.io import read_bytes

pytest.importorskip("laspy", reason="LAS/LAZ need the 'formats' extra (laspy, lazrs)")
pytest.importorskip("lazrs", reason="LAZ needs the 'formats' extra (lazrs)")

from scanner_files import e57_file, las_bytes  # noqa: E402
from test_io_fuzz import corruptions  # noqa: E402


def _e57_bytes(tmp_path_factory) -> bytes:
    pytest.importorskip("pye57", reason="E57 needs the 'formats' extra (pye57)")
    path = tmp_path_factory.mktemp("e57") / "seed.e57"
    e57_file(path, scans=((0, 0, 0), (1, 2, 3)), n=20)
    return path.read_bytes()


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    return {"las": ("las", las_bytes()), "laz": ("laz", las_bytes(compress=True)),
            "las14": ("las", las_bytes("1.4", 7)), "e57": ("e57", _e57_bytes(tmp_path_factory))}


@pytest.mark.parametrize("name", ["las", "laz", "las14", "e57"])
def test_corrupted_scanner_files_raise_only_format_errors(seeds, name):
    fmt, seed = seeds[name]
    assert len(read_bytes(seed, fmt)) >= 10

    @settings(max_examples=40, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture])
    @given(corruptions(seed))
    def check(data):
        try:
            cloud = read_bytes(data, fmt)
        except FormatError:
            return
        assert cloud.points.shape[1] == 3 and len(cloud) >= 10

    check()


def test_lying_point_counts_are_refused_before_decoding(seeds):
    import struct

    _, las = seeds["las"]
    # LAS 1.2 legacy point count at byte 107
    lying = las[:107] + struct.pack("<I", 4_000_000_000) + las[111:]
    with pytest.raises(FormatError, match="header says 4000000000 points"):
        read_bytes(lying, "las")
    _, laz = seeds["laz"]
    lying = laz[:107] + struct.pack("<I", 4_000_000_000) + laz[111:]
    with pytest.raises(FormatError, match="says 4000000000 points"):
        read_bytes(lying, "laz")


def test_lying_laz_chunk_count_is_refused_before_lazrs_allocates(seeds):
    """A fuzzed LAZ whose chunk table claimed 2,557,774,940 chunks made lazrs ask for 40 GB
    and abort the process when the allocation failed."""
    import struct

    _, laz = seeds["laz"]
    start = struct.unpack_from("<I", laz, 96)[0]
    table = struct.unpack_from("<q", laz, start)[0]
    lying = laz[:table + 4] + struct.pack("<I", 2_557_774_940) + laz[table + 8:]
    with pytest.raises(FormatError, match="chunk table lists 2557774940 chunks") as err:
        read_bytes(lying, "laz", source="scan.laz")
    assert err.value.offset == table + 4 and "scan.laz" in str(err.value)
    outside = laz[:start] + struct.pack("<q", len(laz) + 100) + laz[start + 8:]
    with pytest.raises(FormatError, match="chunk table offset"):
        read_bytes(outside, "laz")
