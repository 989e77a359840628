"""core.simd: the four-lane texel sums the compiled kernels read RGBA textures with."""

import numba
import numpy as np
import pytest

from arsim.core.simd import accumulate_texels


@numba.njit
def _accumulate(acc, flat, index, weights):
    return accumulate_texels(acc, flat, index, weights)


def test_accumulate_texels_is_the_weighted_sum_of_four_texels_lane_by_lane():
    rng = np.random.default_rng(0)
    flat = rng.normal(size=4 * 40).astype(np.float32)
    texels = flat.reshape(40, 4).astype(np.float64)
    for _ in range(20):
        index = tuple(int(i) for i in rng.integers(0, 40, 4))  # (repeats allowed: a clamped edge reads one twice)
        weights = tuple(np.float32(w) for w in rng.normal(size=4))
        acc = tuple(np.float32(a) for a in rng.normal(size=4))
        expected = np.array(acc, dtype=np.float64) + sum(w * texels[i] for w, i in zip(np.float64(weights), index))
        got = np.array(_accumulate(acc, flat, index, weights))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5 * np.abs(texels).max())


def test_accumulate_texels_takes_only_float32_texels():
    zero = np.float32(0.0)
    with pytest.raises(numba.core.errors.TypingError):
        _accumulate((zero,) * 4, np.zeros(16), (0, 1, 2, 3), (zero,) * 4)
