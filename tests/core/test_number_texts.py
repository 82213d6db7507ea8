"""Numbers written as text (CSV, ASCII PLY) read back exactly."""

from __future__ import annotations

import numpy as np
import pytest

from curvature.io.tokens import number_texts


@pytest.mark.parametrize("dtype", [np.float64, np.float32, ">f8", np.float16])
def test_floats_read_back_bit_for_bit(dtype):
    rng = np.random.default_rng(1)
    finfo = np.finfo(np.dtype(dtype).newbyteorder("="))
    values = np.concatenate([
        rng.normal(size=500) * 10.0 ** rng.integers(finfo.minexp // 4, finfo.maxexp // 4, 500),
        [0.0, -0.0, finfo.max, -finfo.max, finfo.tiny, finfo.smallest_subnormal, 0.1, 1 / 3],
    ]).astype(dtype)
    texts = number_texts(values)
    back = np.array([float(t) for t in texts]).astype(dtype)
    np.testing.assert_array_equal(back, values)
    assert np.array_equal(np.signbit(back), np.signbit(values))  # -0.0 keeps its sign


def test_non_finite_integers_and_booleans():
    assert number_texts(np.array([np.nan, np.inf, -np.inf, 2.5])) == ["nan", "inf", "-inf",
                                                                        "2.5"]
    assert number_texts(np.array([np.nan], np.float32)) == ["nan"]
    assert number_texts(np.array([-3, 7], np.int8)) == ["-3", "7"]
    assert number_texts(np.array([2**63 - 1], np.int64)) == [str(2**63 - 1)]
    assert number_texts(np.array([True, False])) == ["1", "0"]
    assert number_texts(np.array([], np.float64)) == []
