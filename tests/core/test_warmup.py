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
