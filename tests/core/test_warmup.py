"""The install-time warm-up reaches every numba kernel and records the cache state."""

from __future__ import annotations

import os

from numba import njit

from curvature import warmup


def test_the_warm_up_leaves_no_kernel_uncompiled():
    lines = []
    assert warmup.run(report=lines.append) == []
    assert len(lines) == len(list(warmup.steps())) + 1
    assert lines[-1].startswith("kernels ready in ")
    assert warmup.cache_is_warm()
    assert len(dict(warmup.kernels())) > 50  # every module's kernels were found


def test_a_kernel_nothing_calls_is_reported(monkeypatch):
    @njit(cache=False)
    def _never_called(x):
        return x + 1

    found = dict(warmup.kernels())
    found["curvature.fake._never_called"] = _never_called
    monkeypatch.setattr(warmup, "kernels", lambda: iter(found.items()))
    assert warmup.uncompiled() == ["curvature.fake._never_called"]


def test_a_changed_source_makes_the_cache_cold(tmp_path, monkeypatch):
    (tmp_path / "kernels.py").write_text("x = 1\n")
    monkeypatch.setattr(warmup, "PACKAGE", tmp_path)
    monkeypatch.setattr(warmup, "STAMP", tmp_path / "kernels.warm")
    assert not warmup.cache_is_warm()  # never warmed
    warmup.STAMP.write_text(warmup.fingerprint())
    assert warmup.cache_is_warm()
    stat = (tmp_path / "kernels.py").stat()
    os.utime(tmp_path / "kernels.py", ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert not warmup.cache_is_warm()


def test_a_stale_cache_is_deleted_before_warming(tmp_path, monkeypatch):
    # numba checks only each kernel's own file: a caller compiled against an old callee in
    # another file would keep running it, so a changed package drops every cached kernel
    (tmp_path / "kernels.py").write_text("x = 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    files = [cache / "kernels.f-1.py311.nbi", cache / "kernels.f-1.py311.1.nbc"]
    for f in files:
        f.write_bytes(b"0")
    monkeypatch.setattr(warmup, "PACKAGE", tmp_path)
    monkeypatch.setattr(warmup, "STAMP", cache / "kernels.warm")
    assert warmup.clear_stale_cache() == 0  # no stamp: a fresh install keeps its files
    warmup.STAMP.write_text(warmup.fingerprint())
    assert warmup.clear_stale_cache() == 0  # warm: nothing changed
    assert all(f.exists() for f in files)
    stat = (tmp_path / "kernels.py").stat()
    os.utime(tmp_path / "kernels.py", ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert warmup.clear_stale_cache() == 2
    assert not any(f.exists() for f in files)
