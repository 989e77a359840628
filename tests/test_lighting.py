"""Map methods with known answers: constants, a single bright texel, rotations, tiling, convergence."""

import numpy as np
import pytest

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.errors import ArsimError
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.metrics import map_error
from arsim.lighting.accurate import accurate_maps, lobe_average_at, tiles
from arsim.lighting.fast import fast_maps, order_for_exponent
from arsim.lighting.mc import mc_maps
from arsim.lighting.methods import METHODS, MapParameters, bake
from arsim.lighting.mipmap import mip_chain, mipmap_level
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh import sh_coefficients, sh_maps
from tests.conftest import ENVMAPS

N = 32
INSIDE = anglemap_disk_mask(N)


@pytest.fixture(scope="module")
def courtyard32():
    return to_layout(read_hdr(ENVMAPS[1]), "anglemap", N)


def bright_texel_env(n: int, row: int, col: int, value: float = 100.0) -> np.ndarray:
    env = np.zeros((n, n, 3), dtype=np.float32)
    env[row, col] = value
    return env


# Tolerance of each method on a constant environment. The SH method of the thesis (Alg. 4.7) does not
# normalise by the texels' own weight sums, so its constant is off by the texel-sum quadrature error.
CONSTANT_TOLERANCE = {"accurate": 1e-6, "bounds": 1e-6, "fast": 1e-5, "mipmap": 1e-6, "mc": 1e-6, "sh": 1e-3,
                     "sht": 1e-5}


@pytest.mark.parametrize("name", list(METHODS))
def test_constant_environment_gives_constant_maps(name):
    env = np.full((64, 64, 3), 2.5, dtype=np.float32)
    params = MapParameters(sh_order=8, samples=8)
    maps = bake(env, [1, 10, 80], name, params).maps
    inside = anglemap_disk_mask(64)
    assert np.all(np.isfinite(maps)) and np.all(maps[:, ~inside] == 0)
    np.testing.assert_allclose(maps[:, inside], 2.5, rtol=CONSTANT_TOLERANCE[name])


@pytest.mark.parametrize("s", [1, 10, 80])
def test_single_bright_texel_gives_the_cos_s_lobe(s):
    n = 64
    row, col = 20, 40  # a texel well inside the disk
    env = bright_texel_env(n, row, col)
    omega = anglemap_directions(n)[row, col]
    w0 = anglemap_solid_angles(n)[row, col]
    dirs = anglemap_directions(n)[INSIDE_64]
    cos_s = np.maximum(0.0, dirs @ omega) ** s
    # The normalised lobe average of one texel: L w0 cos^s / (integral of cos^s) = L w0 (s+1)/(2 pi) cos^s.
    expected = 100.0 * w0 * (s + 1) / (2 * np.pi) * cos_s
    lit = cos_s > 0.05
    for maps in (accurate_maps(env, [s]), fast_maps(env, [s])):
        got = maps[0][INSIDE_64][:, 0]
        np.testing.assert_allclose(got[lit], expected[lit], rtol=0.03)
        assert np.all(np.abs(got[~lit]) <= 100.0 * w0 * (s + 1) / (2 * np.pi) * 0.06)


INSIDE_64 = anglemap_disk_mask(64)


@pytest.mark.parametrize("name", ["accurate", "fast", "sh", "mipmap"])
def test_rotating_the_environment_rotates_the_maps(courtyard32, name):
    # A quarter turn about +z (the angle map's centre) permutes texels exactly: np.rot90 of the image.
    params = MapParameters(sh_order=12)
    maps = bake(courtyard32, [1, 20], name, params).maps
    turned = bake(np.ascontiguousarray(np.rot90(courtyard32)), [1, 20], name, params).maps
    np.testing.assert_allclose(turned, np.rot90(maps, axes=(1, 2)), rtol=1e-6, atol=1e-7 * maps.max())


def test_accurate_tiled_equals_untiled_exactly(courtyard32):
    exponents = [1, 10, 160]
    whole = accurate_maps(courtyard32, exponents)
    for size in (8, 16):
        tiled = np.zeros_like(whole)
        for tile in tiles(N, size):
            part = accurate_maps(courtyard32, exponents, tile=tile)
            sl = (slice(None), slice(tile.row0, tile.row0 + tile.size), slice(tile.col0, tile.col0 + tile.size))
            tiled[sl] = part[sl]
        assert np.array_equal(tiled, whole)


def test_accurate_at_directions_equals_the_maps(courtyard32):
    maps = accurate_maps(courtyard32, [1, 40])
    dirs = anglemap_directions(N)[INSIDE]
    np.testing.assert_allclose(lobe_average_at(courtyard32, [1, 40], dirs).transpose(1, 0, 2), maps[:, INSIDE], rtol=1e-6)


def test_bounds_sums_exactly_the_texels_where_the_lobe_exceeds_the_threshold(courtyard32):
    exact = accurate_maps(courtyard32, [10, 80])
    np.testing.assert_allclose(accurate_maps(courtyard32, [10, 80], bounds_threshold=1e-300), exact, rtol=1e-12)
    bounded = accurate_maps(courtyard32, [10, 80], bounds_threshold=0.03)
    # Oracle: the plain thresholded sum, every output texel against every input texel.
    dirs = anglemap_directions(N)[INSIDE]
    w = anglemap_solid_angles(N)[INSIDE]
    radiance = courtyard32[INSIDE].astype(np.float64)
    for k, s in enumerate([10, 80]):
        f = np.maximum(dirs @ dirs.T, 0.0) ** s
        f[f < 0.03] = 0.0
        expected = (f * w) @ radiance / (f @ w)[:, None]
        np.testing.assert_allclose(bounded[k][INSIDE], expected, rtol=1e-5)


def test_fast_matches_accurate(courtyard32):
    exponents = [1, 2, 10, 80, 320]
    exact = accurate_maps(courtyard32, exponents)
    fast = fast_maps(courtyard32, exponents)
    for k in range(len(exponents)):
        e = map_error(exact[k][INSIDE], fast[k][INSIDE])
        assert e.mean_percent < 0.5 and e.max_percent < 5.0, (exponents[k], e)


def test_sh_error_falls_with_order(courtyard32):
    exact = accurate_maps(courtyard32, [1, 10])
    errors = [[map_error(exact[k][INSIDE], m[INSIDE]).mean_percent for k, m in enumerate(sh_maps(courtyard32, [1, 10], o))]
              for o in (2, 4, 8, 16)]
    for k in range(2):
        column = [row[k] for row in errors]
        assert all(a > b for a, b in zip(column, column[1:])), column


def test_sh_order_3_irradiance_is_ramamoorthi_hanrahan(courtyard32):
    # Their nine basis functions in Cartesian form, projected with the same texel weights.
    d = anglemap_directions(N)[INSIDE]
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    y00, y1, y2a, y20, y22 = 0.5 / np.sqrt(np.pi), np.sqrt(3 / (4 * np.pi)), np.sqrt(15 / (4 * np.pi)), \
        np.sqrt(5 / (16 * np.pi)), np.sqrt(15 / (16 * np.pi))
    basis = np.stack([np.full_like(x, y00), y1 * y, y1 * z, y1 * x, y2a * x * y, y2a * y * z,
                      y20 * (3 * z * z - 1), y2a * x * z, y22 * (x * x - y * y)], axis=1)
    lw = courtyard32[INSIDE].astype(np.float64) * anglemap_solid_angles(N)[INSIDE][:, None]
    L00, L1m1, L10, L11, L2m2, L2m1, L20, L21, L22 = (basis.T @ lw)
    # Eq. 13 of "An efficient representation for irradiance environment maps", with its constants
    # written exactly: c1 = (pi/4) y22, c2 = (2 pi/3) y1 / 2, c3 = 3 (pi/4) y20, c4 = pi y00, c5 = (pi/4) y20.
    c1, c2, c3, c4, c5 = np.pi / 4 * y22, np.pi / 3 * y1, 3 * np.pi / 4 * y20, np.pi * y00, np.pi / 4 * y20
    e = (c1 * L22 * (x * x - y * y)[:, None] + c3 * L20 * (z * z)[:, None] + c4 * L00 - c5 * L20
         + 2 * c1 * (L2m2 * (x * y)[:, None] + L21 * (x * z)[:, None] + L2m1 * (y * z)[:, None])
         + 2 * c2 * (L11 * x[:, None] + L1m1 * y[:, None] + L10 * z[:, None]))
    ours = sh_maps(courtyard32.astype(np.float64), [1], 3)[0][INSIDE]
    np.testing.assert_allclose(ours, e / np.pi, rtol=1e-6)


def test_faithful_sh_equals_stable_at_low_order_and_breaks_beyond_86(courtyard32):
    stable, faithful = sh_coefficients(courtyard32, 20), sh_coefficients(courtyard32, 20, faithful=True)
    np.testing.assert_allclose(faithful, stable, rtol=1e-9, atol=1e-12 * np.abs(stable).max())
    high = sh_coefficients(courtyard32, 100, faithful=True)
    assert np.isfinite(high).all()  # NaN zeroed as Alg. 4.7 does, never passed on
    # (l + |m|)! overflows past 170: bands above 85 lose their high-m coefficients to zero.
    l, m = 99, 90
    assert high[l * (l + 1) + m].tolist() == [0.0, 0.0, 0.0]
    assert np.any(sh_coefficients(courtyard32, 100)[l * (l + 1) + m] != 0)


def test_mc_error_falls_about_as_one_over_sqrt_k(courtyard32):
    exact = accurate_maps(courtyard32, [10])[0][INSIDE]
    errors = [map_error(exact, mc_maps(courtyard32, [10], k, seed=1, filtered=False)[0][INSIDE]).mean_percent
              for k in (4, 16, 64, 256)]
    ratios = [a / b for a, b in zip(errors, errors[1:])]
    assert all(1.5 < r < 2.8 for r in ratios), (errors, ratios)  # 1/sqrt(K): 2 per quadrupling
    filtered = [map_error(exact, mc_maps(courtyard32, [10], k, seed=1)[0][INSIDE]).mean_percent for k in (4, 64)]
    assert filtered[1] < filtered[0]


def test_mc_is_deterministic_per_seed(courtyard32):
    a, b = mc_maps(courtyard32, [10, 40], 8, seed=3), mc_maps(courtyard32, [10, 40], 8, seed=3)
    assert np.array_equal(a, b)
    assert np.array_equal(mc_maps(courtyard32, [40], 8, seed=3)[0], a[1])  # alone or with others
    assert not np.array_equal(mc_maps(courtyard32, [10], 8, seed=4)[0], a[0])


def test_mc_on_lobe_grids_is_as_accurate_as_at_the_texels(monkeypatch):
    """At 64² s = 10 and 20 are estimated on their lobes' grids and read bicubically: on three probes, over
    three seeds, their mean error against brute force stays within 2 % of the error the same samples give at
    every texel (measured: 0.90-1.00 times it on the eight bundled probes)."""
    from arsim.lighting import mc

    n, exponents = 64, [10, 20]
    inside = anglemap_disk_mask(n)
    assert all(mc.lobe_grid(s, int(inside.sum())) is not None for s in exponents)
    envs = [to_layout(read_hdr(ENVMAPS[i]), "anglemap", n).astype(np.float64) for i in (0, 1, 3)]
    gridded = [[mc_maps(env, exponents, 64, seed) for seed in range(3)] for env in envs]
    monkeypatch.setattr(mc, "lobe_grid", lambda exponent, texels: None)  # every lobe at the texels
    for env, grid_maps in zip(envs, gridded):
        exact = accurate_maps(env, exponents)
        at_texels = [mc_maps(env, exponents, 64, seed) for seed in range(3)]
        for k in range(len(exponents)):
            grid_error = np.mean([map_error(exact[k][inside], m[k][inside]).mean_percent for m in grid_maps])
            texel_error = np.mean([map_error(exact[k][inside], m[k][inside]).mean_percent for m in at_texels])
            assert grid_error < 1.02 * texel_error, (exponents[k], grid_error, texel_error)


def test_mc_pattern_is_hammersley_turned_per_texel_by_a_hash():
    from arsim.lighting.mc import hammersley, texel_turns

    u1, u2 = hammersley(4)
    assert u1.tolist() == [0.125, 0.375, 0.625, 0.875] and u2.tolist() == [0.0, 0.5, 0.25, 0.75]
    texels = np.arange(20000)
    turns = texel_turns(0, 10.0, texels)
    assert np.all((turns >= 0) & (turns < 2 * np.pi))
    # uniform on [0, 2 pi): mean pi, variance pi^2 / 3, within a few standard errors of 20000 draws
    assert abs(turns.mean() - np.pi) < 0.05 and abs(turns.var() - np.pi**2 / 3) < 0.1
    assert np.array_equal(texel_turns(0, 10.0, texels[5000:6000]), turns[5000:6000])  # any texel alone
    for other in (texel_turns(1, 10.0, texels), texel_turns(0, 20.0, texels)):
        assert np.corrcoef(turns, other)[0, 1] < 0.05  # another seed or exponent: unrelated turns


def test_mip_chain_is_a_2x2_box_pyramid_and_levels_follow_the_equations():
    img = np.random.default_rng(0).random((8, 8, 3))
    chain = mip_chain(img)
    assert [c.shape[0] for c in chain] == [8, 4, 2, 1]
    np.testing.assert_allclose(chain[1][0, 0], img[:2, :2].mean(axis=(0, 1)))
    np.testing.assert_allclose(chain[-1][0, 0], img.mean(axis=(0, 1)))
    assert mipmap_level(1, 512) == 7  # the 4 x 4 level
    assert mipmap_level(10, 512) == 9 - np.log2(5)
    assert mipmap_level(2048, 512) == 0  # clamped to N


def test_phong_zonal_coefficients_match_the_integral():
    from scipy.integrate import quad
    from scipy.special import eval_legendre

    for s in (1, 3.5, 40):
        k = phong_zonal_coefficients(s, 9)
        direct = [(s + 1) * quad(lambda t: t**s * eval_legendre(l, t), 0, 1, limit=200)[0] for l in range(9)]
        np.testing.assert_allclose(k, direct, atol=1e-12)
    assert np.isfinite(phong_zonal_coefficients(1280, 512)).all()


def test_fast_orders_grow_with_the_exponent():
    orders = [order_for_exponent(s) for s in (1, 80, 320, 1280)]
    assert orders == sorted(orders) and orders[-1] > 180


def test_no_method_returns_nan_or_inf_at_high_orders(courtyard32):
    maps = bake(courtyard32, [1, 1280], "sh", MapParameters(sh_order=128)).maps
    assert np.isfinite(maps).all()
    maps = bake(courtyard32, [1, 1280], "sh", MapParameters(sh_order=100, sh_faithful=True)).maps
    assert np.isfinite(maps).all()


@pytest.mark.parametrize("bad", [[0], [-1], [float("nan")], []])
def test_bad_exponents_are_refused(courtyard32, bad):
    with pytest.raises(ArsimError):
        bake(courtyard32, bad, "fast")


def test_environment_with_nan_is_refused(courtyard32):
    env = courtyard32.copy()
    env[3, 3, 0] = np.nan
    with pytest.raises(ArsimError, match="NaN"):
        bake(env, [1], "accurate")


def test_sh_coefficients_are_texel_sums_of_scipys_spherical_harmonics():
    from scipy.special import sph_harm_y

    from arsim.lighting.sh import sh_angles

    n, order = 24, 7
    env = np.random.default_rng(5).random((n, n, 3))
    inside = anglemap_disk_mask(n)
    theta, phi = sh_angles(anglemap_directions(n)[inside])
    lw = env[inside] * anglemap_solid_angles(n)[inside][:, None]
    expected = np.zeros((order * order, 3))
    for l in range(order):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi)  # Condon-Shortley phase, as eq. 2.27
            real = np.sqrt(2) * (y.real if m > 0 else y.imag) if m else y.real
            expected[l * (l + 1) + m] = real @ lw
    np.testing.assert_allclose(sh_coefficients(env, order), expected, atol=1e-13)
    np.testing.assert_allclose(sh_coefficients(env, order, compiled=False), expected, atol=1e-13)


def test_compiled_sh_coefficients_equal_the_numpy_sums_at_high_order(courtyard32):
    """The numba kernel against the NumPy reference, at an order where the recurrence runs long."""
    env = np.concatenate([courtyard32, np.ones(courtyard32.shape[:2] + (1,))], axis=-1)  # as fast uses it
    compiled, reference = sh_coefficients(env, 60), sh_coefficients(env, 60, compiled=False)
    np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-12 * np.abs(reference).max())


def test_compiled_synthesis_grid_equals_the_numpy_one(courtyard32):
    from arsim.lighting.phong import phong_zonal_coefficients
    from arsim.lighting.sh import sh_synthesis_grid

    coeffs = sh_coefficients(courtyard32, 40)
    kappas = np.stack([phong_zonal_coefficients(s, 40) for s in (1, 40, 320)])
    compiled = sh_synthesis_grid(coeffs, kappas, 161, 320)
    reference = sh_synthesis_grid(coeffs, kappas, 161, 320, compiled=False)
    np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-12 * np.abs(reference).max())
