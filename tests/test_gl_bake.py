"""The maps baked on the GL path against the NumPy oracles (float32 on the GPU against float64): the
accurate maps, bounds-optimised and not, tiled and untiled; a tile touches only its own texels."""

import numpy as np
import pytest

from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.accurate import Tile, accurate_maps
from arsim.lighting.gl_bake import GLAccurateBaker, gl_accurate_maps, tile_offset_scale
from tests.conftest import ENVMAPS

EXPONENTS = [1, 10, 80, 320, 1280]


@pytest.fixture(scope="module")
def gl():
    return create_gl_context()


@pytest.fixture(scope="module")
def env():
    return to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32)


def max_relative(test, reference):
    inside = reference > 0
    assert (test[~inside] == 0).all()
    return float((np.abs(test - reference)[inside] / reference[inside]).max())


@pytest.mark.parametrize("threshold", [None, 0.03])
def test_gl_accurate_maps_equal_the_numpy_reference_tiled_and_untiled(gl, env, threshold):
    reference = accurate_maps(env, EXPONENTS, bounds_threshold=threshold)
    untiled = gl_accurate_maps(env, EXPONENTS, ctx=gl, bounds_threshold=threshold)
    tiled = gl_accurate_maps(env, EXPONENTS, tile_size=8, ctx=gl, bounds_threshold=threshold)
    assert max_relative(untiled, reference) < 1e-3
    assert max_relative(tiled, reference) < 1e-3
    np.testing.assert_array_equal(tiled, untiled)  # a texel's sum does not depend on its tile


def test_a_tile_bakes_only_its_texels_and_untouched_tiles_stay_black(gl, env):
    baker = GLAccurateBaker(env, [1, 80], gl)
    baker.bake_tile(Tile(8, 16, 8))
    maps = baker.read()
    baked = np.zeros((32, 32), bool)
    baked[8:16, 16:24] = True
    assert (maps[:, ~baked] == 0).all()
    assert (maps[:, baked] > 0).all()  # this tile lies inside the disk
    assert tile_offset_scale(Tile(8, 16, 8), 32) == ((0.5, 0.5), 0.25)  # thesis table 4.1's terms
    baker.release()


def test_more_maps_than_attachments_bake_in_several_passes(gl, env):
    exponents = [1, 2, 5, 10, 20, 40, 80, 160, 320, 640]  # ten: two passes of at most eight
    reference = accurate_maps(env, exponents)
    assert max_relative(gl_accurate_maps(env, exponents, ctx=gl), reference) < 1e-3


@pytest.mark.parametrize("exponents", [[1], [1, 2, 5, 10, 20, 40, 80, 160, 320]])
def test_a_pass_of_one_map_bakes(gl, env, exponents):
    """The irradiance map alone (what GGX objects read), and nine maps (a second pass of one): a pass's
    array of one exponent is set as one."""
    reference = accurate_maps(env, exponents)
    assert max_relative(gl_accurate_maps(env, exponents, ctx=gl), reference) < 1e-3


@pytest.mark.parametrize("order", [8, 35])
def test_gl_sh_maps_equal_the_direct_sh_sum_tiled_and_untiled(gl, env, order):
    """Alg. 4.7 on the GL path against sh.py's direct float64 sum of the same coefficients. SH maps ring
    and cross zero, where a relative error means nothing: within 1e-3 relative where the value is at
    least 1 % of the map's largest, and within 1e-4 of the map's largest everywhere."""
    from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
    from arsim.lighting.gl_bake import gl_sh_maps
    from arsim.lighting.phong import phong_zonal_coefficients
    from arsim.lighting.sh import sh_coefficients, sh_evaluate

    coeffs = sh_coefficients(env, order)
    kappas = np.stack([phong_zonal_coefficients(s, order) for s in EXPONENTS])
    inside = anglemap_disk_mask(32)
    reference = np.zeros((len(EXPONENTS), 32, 32, 3))
    reference[:, inside] = sh_evaluate(coeffs, kappas, anglemap_directions(32)[inside])[..., :3]
    untiled = gl_sh_maps(env, EXPONENTS, order, ctx=gl, coeffs=coeffs)
    tiled = gl_sh_maps(env, EXPONENTS, order, tile_size=8, ctx=gl, coeffs=coeffs)
    np.testing.assert_array_equal(tiled, untiled)
    scale = np.abs(reference).max(axis=(1, 2, 3), keepdims=True)
    large = np.abs(reference) >= 0.01 * scale
    assert large.sum() > 0.4 * len(EXPONENTS) * inside.sum() * 3
    assert (np.abs(untiled - reference)[large] / np.abs(reference)[large]).max() < 1e-3
    assert (np.abs(untiled - reference) / scale).max() < 1e-4
    assert (untiled[:, ~inside] == 0).all()


@pytest.mark.parametrize("threshold", [None, 0.03])
def test_a_tile_summed_in_ranges_over_several_calls_equals_it_summed_at_once(gl, env, threshold):
    """What auto does when one tile does not fit a frame: its input texels summed in ranges, the sums
    added by blending, divided after the last."""
    whole = GLAccurateBaker(env, EXPONENTS, gl, threshold)
    parts = GLAccurateBaker(env, EXPONENTS, gl, threshold)
    tile = Tile(8, 8, 8)
    whole.bake_tile(tile)
    total = parts.inputs(tile)
    bounds = [0, total // 3, total // 2, total]
    for first, end in zip(bounds, bounds[1:]):
        parts.bake_range(tile, first, end - first, last=end == total)
    a, b = whole.read(), parts.read()
    assert (a[:, 8:16, 8:16] > 0).all()
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=0)
    reference = accurate_maps(env, EXPONENTS, tile=tile, bounds_threshold=threshold)
    assert max_relative(b, reference) < 1e-3
    whole.release()
    parts.release()


def test_a_tile_of_a_512_probe_sums_all_its_input_texels(gl):
    """A 512² probe has 206 000 input texels; llvmpipe ends a shader's loops after 65 535 iterations, so
    a single draw over them all summed only the first third. Each draw now takes at most PASS_INPUTS."""
    from arsim.lighting.gl_bake import PASS_INPUTS

    big = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 512)
    tile = Tile(64, 128, 4)  # looks up: three quarters of the disk lies within 90 degrees
    baker = GLAccurateBaker(big, [1, 80], gl)
    assert baker.inputs(tile) > 2 * 65535 and baker.inputs(tile) > 3 * PASS_INPUTS
    baker.bake_tile(tile)
    test = baker.read()[:, 64:68, 128:132]
    reference = accurate_maps(big, [1, 80], tile=tile)[:, 64:68, 128:132]
    assert max_relative(test, reference) < 1e-3
    baker.release()


@pytest.mark.parametrize("threshold", [None, 0.03])
def test_spans_merged_to_fit_the_uniform_block_give_the_same_sums(gl, env, threshold, monkeypatch):
    """More spans than a draw takes: the closest are merged, and the texels between add nothing."""
    import arsim.lighting.gl_bake as gl_bake

    tile = Tile(8, 8, 8)
    whole = GLAccurateBaker(env, EXPONENTS, gl, threshold)
    whole.bake_tile(tile)
    monkeypatch.setattr(gl_bake, "MAX_SPANS", 4)
    merged = GLAccurateBaker(env, EXPONENTS, gl, threshold)
    assert len(merged._tile_spans(tile)) > 4
    assert len(merged._range_spans(tile, 0, merged.inputs(tile))) <= 4
    merged.bake_tile(tile)
    np.testing.assert_array_equal(merged.read(), whole.read())
    whole.release()
    merged.release()


@pytest.mark.parametrize("name", ["accurate", "bounds"])
def test_bake_by_name_takes_the_gl_path_when_given_a_context(gl, env, name):
    from arsim.lighting.methods import bake

    reference = bake(env, EXPONENTS, name)
    on_gl = bake(env, EXPONENTS, name, gl=gl)
    assert reference.computed_on == "numpy" and on_gl.computed_on.startswith("gl: ")
    assert max_relative(on_gl.maps, reference.maps) < 1e-3
    assert bake(env, EXPONENTS, "mipmap", gl=gl).computed_on == "numpy"  # no GL bake of its own
