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


def test_the_kernels_give_the_same_bits_compiled_afresh_and_loaded_from_numba_cache(tmp_path):
    """Two processes sharing a new numba cache folder: the first compiles the kernels that read texels as vectors
    (mc's reads, the bicubic lookups of sht and mc), the second loads them from the cache; their maps are the
    same bits (tests/test_cli_maps.py compares a bake's file with maps made in the test's process)."""
    import os
    import subprocess
    import sys

    script = """
import sys
import numpy as np
from arsim.core.assets import assets_dir
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.mc import mc_maps
from arsim.lighting.sht import sht_maps
env = to_layout(read_hdr(assets_dir() / "envmaps" / "courtyard.exr"), "anglemap", 32).astype(np.float64)
np.save(sys.argv[1], np.concatenate([mc_maps(env, [1, 10, 40], 16, seed=2), sht_maps(env, [1, 10, 1280])]))
"""
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    for name in ("fresh", "cached"):
        done = subprocess.run([sys.executable, "-c", script, str(tmp_path / f"{name}.npy")], env=environment,
                              capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr
    assert any((tmp_path / "cache").rglob("*.nbc"))  # (the second process had a cache to load)
    assert np.array_equal(np.load(tmp_path / "fresh.npy"), np.load(tmp_path / "cached.npy"))
