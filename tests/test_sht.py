"""`sht` (ducc0's fast SH transforms) and `sh` on them: accuracy against brute force, agreement with the
ring sums that preceded them, the conversions between ducc0's alm and the real SH, the windows."""

import numpy as np
import pytest

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, equirect_directions, equirect_solid_angles
from arsim.core.errors import ArsimError
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.metrics import map_error
from arsim.lighting.accurate import accurate_maps
from arsim.lighting.mc import lobe_grid, mc_maps
from arsim.lighting.methods import MapParameters, bake
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh import (GRID_MAX_ORDER, MAX_ORDER, WINDOWS, _disk_sampler, sh_coefficients, sh_evaluate, sh_maps,
                               sh_synthesis_grid, sh_window, synthesis_grid_size)
from arsim.lighting.sht import (TRUNCATION, alm_from_real, bands_for_exponent, grid_directions, real_from_alm, sh_angles,
                               sht_maps, sht_maps_from_source)
from tests.conftest import ENVMAPS

EXPONENTS = [1, 2, 10, 20, 40, 80, 160, 320, 1280]


@pytest.fixture(scope="module")
def bright64():
    """A real probe at 64² with a small source far brighter than the rest (where truncation shows)."""
    env = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 64).astype(np.float64)
    env[20, 41] += 2000.0
    return env


def test_sht_maps_meet_the_targets_against_brute_force(bright64):
    inside = anglemap_disk_mask(64)
    exact = accurate_maps(bright64, EXPONENTS)
    maps = sht_maps(bright64, EXPONENTS)
    assert maps.dtype == np.float32 and np.all(maps[:, ~inside] == 0)
    for k, s in enumerate(EXPONENTS):
        e = map_error(exact[k][inside], maps[k][inside])
        assert e.mean_percent <= 0.3 and e.max_percent <= 3.0, (s, e)


def test_sht_is_a_method_and_rotates_with_the_probe(bright64):
    maps = bake(bright64, [1, 80], "sht").maps
    turned = bake(np.ascontiguousarray(np.rot90(bright64)), [1, 80], "sht").maps
    np.testing.assert_allclose(turned, np.rot90(maps, axes=(1, 2)), rtol=1e-5, atol=1e-6 * maps.max())


def test_bands_carry_the_lobe_down_to_the_truncation():
    previous = 0
    for s in EXPONENTS:
        bands = bands_for_exponent(s)
        kappa = phong_zonal_coefficients(s, bands + 200)
        assert np.all(np.abs(kappa[bands:]) < TRUNCATION)
        if s >= 10:  # narrower lobes need more bands
            assert bands >= previous
            previous = bands
    # ... but the kink of max(0, cos)^s at the horizon decays like l^-(s+1.5): the smallest s need the most
    assert bands_for_exponent(1) > bands_for_exponent(2) > bands_for_exponent(10)


def test_alm_conversion_round_trips():
    order = 9
    coeffs = np.random.default_rng(0).normal(size=(order * order, 2))
    np.testing.assert_allclose(real_from_alm(alm_from_real(coeffs, order), order), coeffs, atol=1e-15)


@pytest.mark.parametrize("order", [1, 6, 16, 17, 40])
def test_sh_matches_the_ring_sums_within_1e_6(order):
    """The coefficients and maps of `sh` against the NumPy ring sums and evaluations they replaced
    (direct at the texels up to order 16, the bilinear grid beyond)."""
    rng = np.random.default_rng(order)
    n = 32
    env = rng.random((n, n, 3)) * np.array([1.0, 2.0, 3.0])
    env[9, 20] = 500.0
    inside = anglemap_disk_mask(n)
    reference = sh_coefficients(env, order, compiled=False)
    coeffs = sh_coefficients(env, order)
    assert np.abs(coeffs - reference).max() <= 1e-9 * np.abs(reference).max()
    exponents = [1, 20, 1280]
    kappas = np.stack([phong_zonal_coefficients(s, order) for s in exponents])
    if order <= 16:
        old = sh_evaluate(reference, kappas, anglemap_directions(n)[inside])
    else:
        size = synthesis_grid_size(order)
        grid = sh_synthesis_grid(reference, kappas, *size, compiled=False)
        flat = _disk_sampler(n, *size)(grid.reshape((-1,) + grid.shape[2:]))
        old = flat.reshape(flat.shape[0], len(exponents), -1).transpose(1, 0, 2)
    new = sh_maps(env, exponents, order)
    for k in range(len(exponents)):
        np.testing.assert_allclose(new[k][inside], old[k], rtol=1e-6, atol=1e-6 * np.abs(old[k]).max())


@pytest.mark.parametrize("window", ["none", "hann"])
def test_sh_bakes_every_low_order_map_in_one_pass_as_map_by_map(bright64, window):
    """Up to RINGS_MAX_ORDER a bake of `sh` evaluates all its maps in one pass over the rings: the same maps,
    to the bit, as sh_maps gives one exponent at a time."""
    from arsim.lighting.sh import RINGS_MAX_ORDER

    exponents = [1, 10, 80, 1280]
    for order in (5, RINGS_MAX_ORDER):
        baked = bake(bright64, exponents, "sh", MapParameters(sh_order=order, sh_window=window)).maps
        one_by_one = np.stack([sh_maps(bright64, [s], order, window=window)[0] for s in exponents])
        np.testing.assert_array_equal(baked, one_by_one)


@pytest.mark.parametrize("n", [2, 8, 64])
@pytest.mark.parametrize("normalise", [False, True])
def test_sh_low_orders_are_the_series_at_every_texel(n, normalise):
    """Up to RINGS_MAX_ORDER the maps come from one pass over the rings and the square grid's symmetry orbits
    (sh_kernel.orbit_series: each orbit's azimuthal sums once, combined for its up to eight texels): the series
    evaluated directly at each texel's own direction (sh_evaluate), normalised or not, on maps small enough to
    have orbits of one, four and eight texels."""
    from arsim.lighting.sh import RINGS_MAX_ORDER, probe_with_weights

    env = np.random.default_rng(n).random((n, n, 3)) * np.array([1.0, 3.0, 9.0])
    inside = anglemap_disk_mask(n)
    exponents = [1, 10, 1280]
    for order in (1, 4, RINGS_MAX_ORDER):
        coeffs = sh_coefficients(probe_with_weights(env) if normalise else env, order)
        kappas = np.stack([phong_zonal_coefficients(s, order) for s in exponents])
        direct = sh_evaluate(coeffs, kappas, anglemap_directions(n)[inside])
        if normalise:
            den = direct[..., 3:]
            direct = np.divide(direct[..., :3], den, out=np.zeros_like(direct[..., :3]), where=den > 0)
        maps = sh_maps(env, exponents, order, normalise=normalise)
        assert np.all(maps[:, ~inside] == 0)
        for k in range(len(exponents)):
            np.testing.assert_allclose(maps[k][inside], direct[k], rtol=1e-6, atol=1e-7 * np.abs(direct[k]).max())


@pytest.mark.parametrize("order", [4, 40])
@pytest.mark.parametrize("normalise", [False, True])
def test_sh_maps_of_a_grey_probe_are_grey(order, normalise):
    """A one-channel probe gives grey maps: each colour the map of the same values in three channels, on the low
    orders' orbit pass (4) and on the grid's lookups (40), which both write the maps themselves."""
    grey = np.random.default_rng(order).random((16, 16, 1)) * 4.0
    maps = sh_maps(grey, [1, 20], order, normalise=normalise)
    np.testing.assert_array_equal(maps, sh_maps(np.repeat(grey, 3, axis=2), [1, 20], order, normalise=normalise))
    assert np.ptp(maps, axis=-1).max() == 0 and np.abs(maps).max() > 0


def test_sh_beyond_the_grid_orders_is_evaluated_at_the_texels():
    n, order = 16, GRID_MAX_ORDER + 8
    env = np.random.default_rng(1).random((n, n, 3))
    inside = anglemap_disk_mask(n)
    coeffs = sh_coefficients(env, order)
    kappas = phong_zonal_coefficients(1280, order)[None]
    direct = sh_evaluate(coeffs, kappas, anglemap_directions(n)[inside])[0]
    np.testing.assert_allclose(sh_maps(env, [1280], order, coeffs=coeffs)[0][inside], direct, rtol=1e-6,
                               atol=1e-6 * np.abs(direct).max())


def test_sh_narrow_lobes_at_high_grid_orders_are_evaluated_at_the_texels():
    """Above GRID_SPARED_FROM a lobe of few bands skips the order's grid: exact at the texels, and the
    bands beyond carrying_bands (zonal factor under 1e-12) change nothing."""
    from arsim.lighting.sh import BAND_NEGLIGIBLE, GRID_SPARED_FROM, carrying_bands

    n, order = 16, GRID_SPARED_FROM + 8
    env = np.random.default_rng(2).random((n, n, 3))
    env[5, 9] = 300.0
    inside = anglemap_disk_mask(n)
    coeffs = sh_coefficients(env, order)
    kappas = np.stack([phong_zonal_coefficients(s, order) for s in (40, 1280)])
    assert carrying_bands(kappas[0]) < order and abs(kappas[0][carrying_bands(kappas[0])]) < BAND_NEGLIGIBLE
    direct = sh_evaluate(coeffs, kappas, anglemap_directions(n)[inside])  # every band
    maps = sh_maps(env, [40, 1280], order, coeffs=coeffs)
    for k in range(2):
        np.testing.assert_allclose(maps[k][inside], direct[k], rtol=1e-6, atol=1e-6 * np.abs(direct[k]).max())


def test_sh_order_range_and_windows_are_checked():
    MapParameters(sh_order=MAX_ORDER).check()
    assert MAX_ORDER == 1024
    for bad in (MapParameters(sh_order=MAX_ORDER + 1), MapParameters(sh_window="box"),
                MapParameters(sh_order=GRID_MAX_ORDER + 1, sh_faithful=True)):
        with pytest.raises(ArsimError):
            bad.check()


@pytest.mark.parametrize("window", WINDOWS)
def test_windows_keep_the_mean_and_fall_with_band(window):
    w = sh_window(window, 20)
    assert w[0] == 1.0 and np.all(np.diff(w) <= 0) and np.all(w > 0)
    env = np.full((64, 64, 3), 1.5)  # 64²: as test_lighting holds sh's constant
    maps = bake(env, [1, 40], "sh", MapParameters(sh_order=20, sh_window=window)).maps
    np.testing.assert_allclose(maps[:, anglemap_disk_mask(64)], 1.5, rtol=1e-3)


def test_windows_reduce_ringing_around_a_bright_source(bright64):
    """Plain truncation rings: negative lobes round a small bright source. Hann and Sloan's windows
    shrink the most negative value of the map (the ringing Sloan's tricks remove)."""
    plain = sh_maps(bright64, [1280], 12)[0][..., 0].min()
    assert plain < 0
    for window in ("hann", "sloan"):
        assert sh_maps(bright64, [1280], 12, window=window)[0][..., 0].min() > 0.5 * plain


@pytest.mark.parametrize("path", ENVMAPS, ids=lambda p: p.stem)
def test_windowed_sh_falls_with_order_at_every_exponent_on_every_bundled_asset(path):
    """Each window's error against the accurate maps, by its mean per-texel relative error and by its relative
    RMS, falls (or stays) from order 2 to 64 at all nine exponents, on every bundled probe at 64²; plain
    truncation does not (it rings: e.g. its error at s = 10 rises from order 16 to 32)."""
    env = to_layout(read_hdr(path), "anglemap", 64)
    inside = anglemap_disk_mask(64)
    reference = accurate_maps(env, EXPONENTS)[:, inside]
    orders = [2, 4, 8, 16, 32, 64]
    rising_plain = 0
    for window in WINDOWS:
        mean = np.zeros((len(orders), len(EXPONENTS)))
        rms = np.zeros_like(mean)
        for i, order in enumerate(orders):
            maps = bake(env, EXPONENTS, "sh", MapParameters(sh_order=order, sh_window=window)).maps[:, inside]
            for k in range(len(EXPONENTS)):
                mean[i, k] = map_error(reference[k], maps[k]).mean_percent
                rms[i, k] = np.sqrt(np.mean((maps[k] - reference[k]) ** 2) / np.mean(reference[k] ** 2))
        if window == "none":
            rising_plain = int(np.sum(np.diff(rms, axis=0) > 0))
            continue
        assert np.all(np.diff(mean, axis=0) <= 1e-12), (window, mean)
        assert np.all(np.diff(rms, axis=0) <= 1e-12), (window, rms)
    assert rising_plain > 0  # the ringing the windows remove


@pytest.mark.parametrize("filtered", [True, False])
@pytest.mark.parametrize("step", [1, 2])
def test_mc_compiled_equals_its_numpy_path(bright64, filtered, step):
    """mc's compiled samples: the same uniforms, directions, levels and lookups as the NumPy path, at the
    texels and (64²: s = 10 and 20) at the points of a lobe's grid."""
    env = bright64[::step, ::step].copy()
    exponents = [1, 10, 20, 1280]
    on_grids = [lobe_grid(s, int(anglemap_disk_mask(env.shape[0]).sum())) is not None for s in exponents]
    assert on_grids == ([False, True, True, False] if step == 1 else [False] * 4)
    fast = mc_maps(env, exponents, 16, seed=3, filtered=filtered)
    slow = mc_maps(env, exponents, 16, seed=3, filtered=filtered, compiled=False)
    np.testing.assert_allclose(fast, slow, rtol=1e-5, atol=1e-6 * slow.max())


def test_grid_directions_are_the_grid_coordinates_points():
    """The points mc estimates a lobe at (sht.grid_directions) sit where the lookups read the grid
    (sht.sh_angles, as grid_coordinates turns texels into rows and columns): row r, column c exactly."""
    n_theta, n_phi = 9, 16
    theta, phi = sh_angles(grid_directions(n_theta, n_phi))
    rows, cols = theta / np.pi * (n_theta - 1), phi / (2 * np.pi) * n_phi
    r, c = np.divmod(np.arange(n_theta * n_phi), n_phi)
    inner = (r > 0) & (r < n_theta - 1)  # (at the poles every column is the same point: phi is arbitrary)
    np.testing.assert_allclose(rows, r, atol=1e-9)
    np.testing.assert_allclose(cols[inner], c[inner], atol=1e-9)


def test_sht_from_the_source_itself(bright64):
    """From an angle map it is `sht`; from an equirect it sums the equirect's own texels, and agrees with
    brute force over those texels."""
    np.testing.assert_allclose(sht_maps_from_source(bright64, 64, [1, 80]), sht_maps(bright64, [1, 80]), rtol=1e-4,
                               atol=1e-5 * bright64.max())
    equirect = read_hdr(ENVMAPS[1])[::8, ::8].astype(np.float64)  # 64 x 128
    equirect[20, 70] += 500.0
    maps = sht_maps_from_source(equirect, 32, [1, 80])
    inside = anglemap_disk_mask(32)
    dirs = anglemap_directions(32)[inside]
    src_dirs = equirect_directions(64).reshape(-1, 3)
    w = equirect_solid_angles(64).ravel()
    for k, s in enumerate([1, 80]):
        lobe = np.maximum(dirs @ src_dirs.T, 0.0) ** s * w
        exact = (lobe @ equirect.reshape(-1, 3)) / lobe.sum(axis=1)[:, None]
        e = map_error(exact, maps[k][inside])
        assert e.mean_percent <= 0.3 and e.max_percent <= 3.0, (s, e)


def test_sh_sums_an_equirect_at_its_own_resolution():
    """`sh` given an equirect larger than its map sums the equirect's own texels: its coefficients are the
    NumPy sums sum_i L_i Y_lm(w_i) W_i over them, and the bake says so; --sh-faithful keeps the angle map."""
    from arsim.lighting.sh import sh_evaluate
    from arsim.lighting.sht import equirect_texel_sums

    equirect = read_hdr(ENVMAPS[2])[::16, ::16].astype(np.float64)  # 32 x 64
    equirect[5, 40] += 400.0
    order = 6
    basis = sh_evaluate(np.eye(order * order), np.ones((1, order)), equirect_directions(32).reshape(-1, 3))[0]
    exact = basis.T @ (equirect.reshape(-1, 3) * equirect_solid_angles(32).reshape(-1, 1))
    np.testing.assert_allclose(equirect_texel_sums(equirect, order), exact, rtol=0, atol=1e-10 * np.abs(exact).max())
    env = to_layout(equirect, "anglemap", 16)
    params = MapParameters(sh_order=order)
    baked = bake(env, [1, 20], "sh", params, source=equirect)
    assert baked.summed_over == "equirect 64x32 at its own resolution"
    np.testing.assert_allclose(baked.maps, sh_maps(env, [1, 20], order, coeffs=exact), rtol=1e-6, atol=1e-9)
    faithful = bake(env, [1, 20], "sh", MapParameters(sh_order=order, sh_faithful=True), source=equirect)
    assert faithful.summed_over == "angle map"


def test_texel_sums_are_the_same_bits_while_the_cores_are_busy():
    """The adjoint transform's sums do not depend on its threads' timing: with another thread keeping a core
    busy (where ducc0's own threads on one channel gave different last bits nearly every time), every
    repetition equals the first, bit for bit."""
    import threading

    from arsim.lighting.sht import FAST_EPSILON, adjoint_at, disk_locations

    loc = disk_locations(128)
    planes = np.random.default_rng(0).random((3, len(loc))).astype(np.float32)
    stop = threading.Event()

    def busy():
        a = np.random.default_rng(1).random((200, 200))
        while not stop.is_set():
            a @ a

    worker = threading.Thread(target=busy)
    worker.start()
    try:
        first = adjoint_at(planes, loc, 40, FAST_EPSILON)
        assert all(np.array_equal(adjoint_at(planes, loc, 40, FAST_EPSILON), first) for _ in range(20))
    finally:
        stop.set()
        worker.join()


@pytest.mark.parametrize("cores", [1, 2, 3, 5])
def test_texel_sums_cut_into_a_run_per_core_are_each_channels_whole_transform(monkeypatch, cores):
    """The channels laid end to end and cut into a run per core (sht.work_runs) cover every texel of every
    channel once, in runs of equal length; the pieces' sums are each whole channel's transform."""
    import ducc0

    from arsim.lighting import sht

    runs = sht.work_runs(3, 1000, cores)
    counts = np.zeros((3, 1000), dtype=int)
    for c, a, b in (piece for pieces in runs for piece in pieces):
        counts[c, a:b] += 1
    lengths = [sum(b - a for _, a, b in pieces) for pieces in runs]
    assert (counts == 1).all() and len(runs) == cores and max(lengths) - min(lengths) <= 1

    monkeypatch.setattr(sht.os, "cpu_count", lambda: cores)
    loc = sht.disk_locations(64)
    planes = np.random.default_rng(0).random((3, len(loc)))
    whole = np.stack([ducc0.sht.experimental.adjoint_synthesis_general(map=p[None], spin=0, lmax=30, loc=loc,
                                                                      epsilon=1e-12, nthreads=1)[0] for p in planes])
    np.testing.assert_allclose(sht.adjoint_at(planes, loc, 30, 1e-12), whole, rtol=0, atol=1e-11 * np.abs(whole).max())


def test_equirect_texel_sums_on_its_rings_are_the_sums_over_its_texels():
    """The ring-based transform of an equirect (rows as rings about +y) gives the exact texel sums
    sum_i L_i conj(Y_lm(w_i)) W_i at each texel's direction in that frame (theta = pi v, phi = 2 pi u),
    as the non-uniform transform over the same texels does."""
    import ducc0

    from arsim.core.conventions import equirect_texel_uv
    from arsim.lighting.sht import _equirect_alm

    equirect = read_hdr(ENVMAPS[0])[::8, ::8].astype(np.float64)  # 64 x 128
    equirect[9, 100] += 300.0
    planes = np.moveaxis(equirect, 2, 0)
    rings = _equirect_alm(planes, 40)
    uv = equirect_texel_uv(64).reshape(-1, 2)
    loc = np.stack([np.pi * uv[:, 1], 2 * np.pi * uv[:, 0]], axis=1)
    w = equirect_solid_angles(64).ravel()
    texels = np.stack([ducc0.sht.experimental.adjoint_synthesis_general(
        map=(p.ravel() * w)[None], spin=0, lmax=40, loc=loc, epsilon=1e-12)[0] for p in planes])
    np.testing.assert_allclose(rings, texels, rtol=0, atol=2e-6 * np.abs(texels).max())
