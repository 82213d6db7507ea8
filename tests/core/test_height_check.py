"""A clean cloud's implicit quadric must be confirmed by the height quadric over its points
(curvature.fitting.height_check)."""

from __future__ import annotations

import numpy as np
import pytest
from sine_waves import sine_wave, wave_errors

import curvature
from curvature.fitting.height_check import AGREE, CLOSE, RATIO, unconfirmed


def _check(k, m, h):
    """``unconfirmed`` for one fit: k and m are (k1, k2) pairs."""
    return bool(unconfirmed(np.array([k[0]]), np.array([k[1]]), np.array([m[0]]),
                            np.array([m[1]]), np.array([h]))[0])


def test_fits_that_agree_in_either_sign_convention_are_confirmed():
    assert not _check((2.0, 0.5), (2.05, 0.48), 0.05)
    # the height fit's normal the other way round: (-0.48, -2.05) is the same surface
    assert not _check((2.0, 0.5), (-0.48, -2.05), 0.05)
    # a failed height fit never takes an implicit one away
    assert not _check((40.0, 0.5), (np.nan, np.nan), 0.05)


def test_an_implicit_fit_bending_far_more_than_the_height_fit_is_unconfirmed():
    # a sine wave's blow-up: 20 where the height fit reads 0.6 over h = 0.017
    assert _check((20.0, -0.1), (0.6, 0.0), 0.017)
    # with no overshoot of RATIO: just past AGREE plus the bend's allowance, and just within
    h, m = 0.1, 3.0
    allow = (AGREE + (m * h) ** 3) / h
    assert m + 1.03 * allow < RATIO * m
    assert _check((m + 1.03 * allow, 0.0), (m, 0.0), h)
    assert not _check((m + 0.97 * allow, 0.0), (m, 0.0), h)
    # past CLOSE (dk h = 0.05) but under AGREE: unconfirmed where the implicit fit reads
    # twice the height fit's curvature, left alone where it reads 4 / 3 of it
    assert CLOSE < 0.05 < AGREE and 4.0 / 3.0 < RATIO < 2.0
    assert _check((2.0, 0.0), (1.0, 0.0), 0.05)
    assert not _check((4.0, 0.0), (3.0, 0.0), 0.05)


def test_a_tight_bend_allows_the_height_fits_own_bias():
    # k h = 0.5: the height quadric underestimates a few-spacing fillet; a difference of
    # 0.15 / h is within AGREE + (k h)^3 = 0.225 and no overshoot of RATIO
    assert not _check((6.5, 0.0), (5.0, 0.0), 0.1)
    # the same difference on a gentle surface is not
    assert _check((1.5 + 1.5, 0.0), (1.5, 0.0), 0.1)


@pytest.mark.parametrize("seed", [5, 6])
def test_a_noise_free_sine_wave_never_reads_beyond_its_curvature(seed):
    """Before the check 40 / 32 interior points read more than the wave's largest curvature
    (3.1), up to 42.6 / 43.1, and the mean error was 0.166 / 0.155; with it the largest error
    is 1.9 / 2.0 and the mean 0.118 / 0.115."""
    pts, normals, k, k_max, inner = sine_wave(seed)
    res = curvature.estimate(pts, normals=normals)
    assert res.info["plan"]["clean"]
    err = wave_errors(res, k)[inner]
    assert np.all(res.status[inner] == 0)
    assert err.max() < 0.8 * k_max
    assert np.mean(err) < 0.045 * k_max
