"""`sht` and `sh` against a plain ducc0 script and against brute force (prints figures; not a test).

    python benchmarks/bench_sht.py [--assets city,interior,sunrise] [--texels 300] [--fine 2048] [--quick]
    python benchmarks/bench_sht.py --speed [--assets city]
    python benchmarks/bench_sht.py --transforms [--assets city]   # ducc0 against SHTns (if installed)
    python benchmarks/bench_sht.py --mc-figure benchmarks/results/mc_grids.png   # mc on grids and at every texel
    python benchmarks/bench_sht.py --speed-figure benchmarks/results/sh_orders_speed.png   # sh's orders and mc, timed

--transforms: the grid syntheses `sht` runs at 512² (each exponent's bandlimit and grid), timed with ducc0 in
double and single precision and with SHTns (double; built from source with FFTW: `apt-get install
libfftw3-dev && pip install shtns`), and `sht` end to end with its syntheses on SHTns. SHTns has no
non-uniform transform, so the exact texel sums stay on ducc0 either way.

--speed: per asset, `mc` at 64 samples against `sh` at order 64 (nine maps each, best of 3, in the same
run: both times and their ratio) with mc's error against brute force, and `mc` at every texel (--mc-texels,
once) likewise, then `sh` at orders 3 to 1024, each
time and its ratio to order 64's (a speed cliff shows as a ratio far from its neighbours').

Per asset (512² angle map of the bundled equirect, nine exponents):
- times, best of 3, with their ratios measured in the same run: `sht` (a bake: shared work + nine maps),
  the peer (a ducc0 script at L = 255: the angle map resampled onto a Gauss-Legendre grid, one analysis,
  nine kernel products and syntheses, bilinear lookups at the texels), `fast`;
- errors (mean/max %, README: Conventions) of `sht` and the peer against brute force at --texels random
  disk texels plus the patch around the brightest texel, from the 512² source and from a --fine² angle map
  of the same equirect (4x finer: what the 512² source itself loses), and of `sht` and `sh` at order 256 summed
  over the equirect's own texels;
- the gap between the two references themselves (brute force over the 512² angle map against the --fine² one,
  at the fine reference's texels): no map can lie within a tolerance of both where they differ by more
  than twice it;
- `sh` at order 256 (coefficients + nine maps) against one ducc0 analysis and nine syntheses of its grid;
- `sh` with each window: mean error against brute force at orders 8..256, and whether it falls with order.
"""

import argparse
import sys
import time
from pathlib import Path

import cv2
import ducc0
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from maps_accuracy import reference_texels  # noqa: E402
from timing import best_of  # noqa: E402

from arsim.core.assets import assets_dir  # noqa: E402
from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles  # noqa: E402
from arsim.core.hdr_io import read_hdr  # noqa: E402
from arsim.core.resample import to_layout  # noqa: E402
from arsim.evaluate.metrics import map_error  # noqa: E402
from arsim.lighting.accurate import lobe_average_at  # noqa: E402
from arsim.lighting.methods import MapParameters, bake  # noqa: E402
from arsim.lighting.phong import phong_zonal_coefficients  # noqa: E402
from arsim.lighting.sh import WINDOWS, synthesis_grid_size  # noqa: E402
from arsim.lighting.sht import disk_locations, sh_angles, sht_maps_from_source  # noqa: E402

EXPONENTS = [1, 2, 10, 20, 40, 80, 160, 320, 1280]
SHT = ducc0.sht.experimental
PEER_LMAX = 255


def peer(env: np.ndarray, exponents) -> np.ndarray:
    """What a short script on ducc0 does: resample the angle map onto the GL grid of L = 255, analyse,
    multiply by the lobe's zonal coefficients, synthesise on the same grid, look the texels up bilinearly."""
    n = env.shape[0]
    lmax = PEER_LMAX
    ntheta, nphi = lmax + 1, 2 * lmax + 2
    theta = np.arccos(np.polynomial.legendre.leggauss(ntheta)[0])[::-1]  # GL nodes, north to south
    phi = 2 * np.pi * np.arange(nphi) / nphi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    # The SH frame of sh.py: pole +z, phi = atan2(d_y, -d_x); angle map s = 0.5 + d_x r/2, t = 0.5 + d_y r/2.
    dx, dy = -np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph)
    r = th / (np.pi * np.maximum(np.sin(th), 1e-12))
    col = ((0.5 + dx * r / 2) * n - 0.5).astype(np.float32)
    row = ((1 - (0.5 + dy * r / 2)) * n - 0.5).astype(np.float32)
    grid = cv2.remap(env.astype(np.float32), col, row, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    alm = [SHT.analysis_2d(map=grid[None, :, :, c].astype(np.float64), spin=0, lmax=lmax, geometry="GL", nthreads=0)
           for c in range(3)]
    loc_t, loc_p = sh_angles(anglemap_directions(n))
    map_row = np.interp(loc_t, theta, np.arange(ntheta)).astype(np.float32)
    map_col = (loc_p / (2 * np.pi) * nphi).astype(np.float32)
    l = np.concatenate([np.arange(m, lmax + 1) for m in range(lmax + 1)])
    out = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    inside = anglemap_disk_mask(n)
    for k, s in enumerate(exponents):
        kappa = phong_zonal_coefficients(s, lmax + 1)[l]
        for c in range(3):
            m = SHT.synthesis_2d(alm=alm[c] * kappa, spin=0, lmax=lmax, geometry="GL", ntheta=ntheta, nphi=nphi,
                                 nthreads=0)[0].astype(np.float32)
            m = np.concatenate([m, m[:, :1]], axis=1)  # wrap in longitude
            out[k, :, :, c] = cv2.remap(m, map_col, map_row, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out[k][~inside] = 0
    return out


def brute_force(env: np.ndarray, exponents, directions: np.ndarray) -> np.ndarray:
    """(K, E, 3) normalised lobe averages over every disk texel of env (any size), direction by direction."""
    n = env.shape[0]
    inside = anglemap_disk_mask(n)
    dirs = anglemap_directions(n)[inside]
    w = anglemap_solid_angles(n)[inside]
    lw = np.concatenate([env[inside].astype(np.float64) * w[:, None], w[:, None]], axis=1)
    out = np.empty((len(directions), len(exponents), 3))
    for i, d in enumerate(directions):
        c = np.maximum(dirs @ d, 0.0)
        keep = c > 0
        c, part = c[keep], lw[keep]
        for k, s in enumerate(exponents):
            sums = (c**s) @ part
            out[i, k] = sums[:3] / sums[3]
    return out


def errors(reference: np.ndarray, maps: np.ndarray, texels: np.ndarray) -> list:
    return [map_error(reference[:, k], maps[k].reshape(-1, 3)[texels]) for k in range(len(EXPONENTS))]


def row(errs) -> str:
    return "  ".join(f"{e.mean_percent:6.3f}/{e.max_percent:5.2f}" for e in errs)


def timed_best(repeat, fn):
    best, result = None, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        t = time.perf_counter() - start
        best = t if best is None else min(best, t)
    return best, result


def wall_and_cpu(repeat, fn):
    """Best wall time, best CPU time (all threads: steadier than wall time on a shared machine), result."""
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - start_cpu)
    return min(walls), min(cpus), result


SWEEP_ORDERS = [3, 5, 10, 16, 17, 32, 64, 128, 256, 512, 1024]


def order_sweep(env: np.ndarray) -> dict[int, float]:
    """Seconds of `sh` (coefficients and the nine maps) at each of SWEEP_ORDERS, best of 3."""
    times = {}
    for order in SWEEP_ORDERS:
        params = MapParameters(sh_order=order)
        bake(env, EXPONENTS, "sh", params)  # warm: the order's own tables
        times[order] = best_of(3, lambda: bake(env, EXPONENTS, "sh", params))
    return times


def speed_figure(path: Path, names) -> None:
    """`sh`'s time over its orders on each asset against twice order 64's (the no-cliff line), with `mc` at 64
    samples beside it: seconds, best of 3, the asset's runs one after another."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axis = plt.subplots(figsize=(7.5, 4.5))
    for k, name in enumerate(names):
        env = to_layout(read_hdr(assets_dir() / "envmaps" / f"{name}.exr"), "anglemap", 512)
        times = order_sweep(env)
        bake(env, EXPONENTS, "mc", MapParameters(samples=64))
        mc_s = best_of(3, lambda: bake(env, EXPONENTS, "mc", MapParameters(samples=64)))
        colour = f"C{k}"
        axis.plot(list(times), list(times.values()), "o-", color=colour, label=f"sh, {name}")
        axis.axhline(2 * times[64], color=colour, linestyle=":", linewidth=1)
        axis.plot([64], [mc_s], "s", color=colour, markersize=8, markerfacecolor="none", label=f"mc, 64 samples, {name}")
        print(f"{name}: " + ", ".join(f"{o}: {t:.3f}" for o, t in times.items()) + f"; mc {mc_s:.3f} s")
    axis.set_xscale("log", base=2)
    axis.set_yscale("log")
    axis.set_xticks(SWEEP_ORDERS, [str(o) if o != 17 else "" for o in SWEEP_ORDERS])  # (17 beside 16: unlabelled)
    axis.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    axis.yaxis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    axis.set_xlabel("SH order (bands)")
    axis.set_ylabel("seconds: coefficients + nine 512² maps")
    axis.set_title("sh over its orders (dotted: twice order 64's time), mc beside order 64", fontsize=10)
    axis.grid(True, which="both", alpha=0.3)
    axis.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f"wrote {path}")


def speed(names, texels: int) -> None:
    """mc at 64 samples against sh at order 64, and sh's time over orders, at 512² (best of 3 each)."""
    for name in names:
        env = to_layout(read_hdr(assets_dir() / "envmaps" / f"{name}.exr"), "anglemap", 512)
        bake(env, EXPONENTS, "sh", MapParameters(sh_order=64))  # warm: compiled kernels, per-size caches
        bake(env[::8, ::8].copy(), EXPONENTS, "mc", MapParameters(samples=64))
        sh_s, sh_cpu, _ = wall_and_cpu(3, lambda: bake(env, EXPONENTS, "sh", MapParameters(sh_order=64)))
        mc_s, mc_cpu, mc_bake = wall_and_cpu(3, lambda: bake(env, EXPONENTS, "mc", MapParameters(samples=64)))
        print(f"\n{name}: nine 512² maps: mc (64 samples) {mc_s:.3f} s, sh (order 64) {sh_s:.3f} s; "
              f"mc/sh64 = {mc_s / sh_s:.2f}x (CPU time of all threads: mc {mc_cpu:.2f} s, sh {sh_cpu:.2f} s, "
              f"{mc_cpu / sh_cpu:.2f}x)")
        picked = reference_texels(env, texels)
        reference = lobe_average_at(env, EXPONENTS, anglemap_directions(512).reshape(-1, 3)[picked])
        e = errors(reference, mc_bake.maps, picked)
        print(f"  mc vs brute force at {len(picked)} texels, mean/max %: {row(e)}; mean over exponents "
              f"{np.mean([x.mean_percent for x in e]):.3f}, worst max {max(x.max_percent for x in e):.2f}")
        texels_s, _, texels_bake = wall_and_cpu(1, lambda: bake(env, EXPONENTS, "mc", MapParameters(samples=64, mc_texels=True)))
        e = errors(reference, texels_bake.maps, picked)
        print(f"  mc at every texel (--mc-texels): {texels_s:.3f} s ({texels_s / sh_s:.2f}x sh64); mean/max %: {row(e)}; "
              f"mean over exponents {np.mean([x.mean_percent for x in e]):.3f}, worst max {max(x.max_percent for x in e):.2f}")
        if name != names[0]:
            continue
        times = order_sweep(env)
        print("  sh by order (nine maps), seconds and ratio to order 64: " + ", ".join(
            f"{o}: {t:.3f} ({t / times[64]:.2f}x)" for o, t in times.items()))
        print(f"  worst ratio {max(times.values()) / times[64]:.2f}x, best {min(times.values()) / times[64]:.2f}x")
        # What the transform itself costs at each order on the same texels (3 analyses and 27 syntheses, all
        # bands, ducc0's non-uniform transforms): its own growth with the order bounds any SH path built on it.
        loc = disk_locations(512)
        values = np.random.default_rng(0).random((1, loc.shape[0]))

        def transforms(order):
            alms = [SHT.adjoint_synthesis_general(map=values, spin=0, lmax=order - 1, loc=loc, epsilon=1e-10, nthreads=0)
                    for _ in range(3)]
            for _ in EXPONENTS:
                for a in alms:
                    SHT.synthesis_general(alm=a, spin=0, lmax=order - 1, loc=loc, epsilon=1e-10, nthreads=0)

        alone = {}
        for order in (64, 256, 512, 1024):
            transforms(order)
            alone[order] = best_of(3, lambda: transforms(order))
        print("  ducc0 alone on the disk texels (3 analyses + 27 syntheses), seconds, its ratio to its order 64, and sh's "
              "time over it: " + ", ".join(f"{o}: {t:.3f} ({t / alone[64]:.2f}x; sh {times[o] / t:.2f}x)" for o, t in alone.items()))


def mc_figure(path: Path, name: str = "night", exponents=(1, 10, 160, 1280)) -> None:
    """mc's maps at 64 samples on the lobes' grids (the default) and at every texel (--mc-texels), side by side:
    the same noise in mean, a grid's grain against a texel's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env = to_layout(read_hdr(assets_dir() / "envmaps" / f"{name}.exr"), "anglemap", 512)
    rows = {"grids (default)": bake(env, exponents, "mc", MapParameters(samples=64)).maps,
            "every texel (--mc-texels)": bake(env, exponents, "mc", MapParameters(samples=64, mc_texels=True)).maps}
    fig, axes = plt.subplots(len(rows), len(exponents), figsize=(3.2 * len(exponents), 3.6 * len(rows)))
    for k, s in enumerate(exponents):
        scale = np.percentile(rows["every texel (--mc-texels)"][k], 99.5)  # (one scale per column: the same light)
        for axis, (label, maps) in zip(axes[:, k], rows.items()):
            axis.imshow(np.clip(maps[k] / scale, 0, 1) ** (1 / 2.2))
            axis.set_title(f"s = {s}, {label}", fontsize=9)
            axis.axis("off")
    fig.suptitle(f"mc, 64 samples, {name}, 512² angle maps (gamma 2.2, each column scaled alike)")
    fig.tight_layout(h_pad=2.0)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    print(f"wrote {path}")


def transforms(names) -> None:
    """ducc0 against SHTns on the syntheses `sht` runs (best of 5, ms), and `sht` with SHTns syntheses."""
    try:
        import shtns
    except ImportError:
        sys.exit("--transforms needs SHTns: apt-get install libfftw3-dev && pip install shtns")
    from arsim.lighting import sht
    from arsim.lighting.sh_kernel import cubic_lookup_into

    plans = {}

    def plan(lmax, n_theta, n_phi):  # SHTns's regular grid with both poles: ducc0's Clenshaw-Curtis geometry
        if (lmax, n_theta, n_phi) not in plans:
            p = shtns.sht(lmax, lmax, 1, shtns.sht_orthonormal)
            p.set_grid(n_theta, n_phi, shtns.sht_reg_poles | shtns.SHT_PHI_CONTIGUOUS, 1e-10)
            plans[lmax, n_theta, n_phi] = p
        return plans[lmax, n_theta, n_phi]

    def grids(lmax):
        for s in EXPONENTS:
            bands = min(sht.bands_for_exponent(s), lmax + 1)
            yield s, bands, sht.grid_size(s, bands)

    def with_shtns(env):
        alm, lmax = sht.sht_prepare(env, EXPONENTS)
        n = env.shape[0]
        l, m, _ = sht._alm_index(lmax)
        out = np.zeros((len(EXPONENTS), n, n, 3), np.float32)
        for k, (s, bands, size) in enumerate(grids(lmax)):
            a = sht.zonal_scale(alm[:, (l < bands) & (m < bands)], phong_zonal_coefficients(s, bands)).astype(np.complex128)
            grid = np.stack([plan(bands - 1, *size).synth(c) for c in a]).astype(np.float32)
            cubic_lookup_into(out[k].reshape(n * n, 3), sht.disk_index(n), grid.reshape(3, -1), *size,
                              *sht.grid_coordinates(n, *size), sht._weight_map(n, float(s), bands))
        return out

    rng = np.random.default_rng(0)
    lmax = max(sht.bands_for_exponent(s) for s in EXPONENTS) - 1
    print("one synthesis per grid sht uses at 512², ms (best of 5): ducc0 double, ducc0 single, SHTns double")
    totals = np.zeros(3)
    for s, bands, (n_theta, n_phi) in grids(lmax):
        nalm = bands * (bands + 1) // 2
        alm = rng.standard_normal(nalm) + 1j * rng.standard_normal(nalm)
        alm[:bands] = alm[:bands].real  # m = 0: real
        p = plan(bands - 1, n_theta, n_phi)
        difference = np.max(np.abs(p.synth(alm) - SHT.synthesis_2d(alm=alm[None], spin=0, lmax=bands - 1, geometry="CC",
                                                                    ntheta=n_theta, nphi=n_phi, nthreads=0)[0]))
        times = [best_of(5, lambda a=a: SHT.synthesis_2d(alm=a[None], spin=0, lmax=bands - 1, geometry="CC", ntheta=n_theta,
                                                          nphi=n_phi, nthreads=0))
                 for a in (alm, alm.astype(np.complex64))] + [best_of(5, lambda: p.synth(alm))]
        totals += times
        print(f"  s = {s:>4}: {bands} bands on {n_theta}x{n_phi}: " + ", ".join(f"{1000 * t:.2f}" for t in times)
              + f"  (SHTns/ducc0 double agree to {difference:.1e})")
    print("  nine maps' syntheses (3 channels each): " + ", ".join(f"{3000 * t:.1f} ms" for t in totals))
    for name in names:
        env = to_layout(read_hdr(assets_dir() / "envmaps" / f"{name}.exr"), "anglemap", 512)
        for f in (lambda: sht.sht_maps(env, EXPONENTS), lambda: with_shtns(env)):
            f()  # warm: plans, per-size caches
        ducc_s = best_of(5, lambda: sht.sht_maps(env, EXPONENTS))
        shtns_s = best_of(5, lambda: with_shtns(env))
        print(f"{name}: sht {1000 * ducc_s:.1f} ms; with SHTns syntheses {1000 * shtns_s:.1f} ms ({ducc_s / shtns_s:.2f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--assets", default="city,interior,sunrise")
    parser.add_argument("--texels", type=int, default=300)
    parser.add_argument("--fine", type=int, default=2048)
    parser.add_argument("--fine-texels", type=int, default=40,
                        help="random texels for the fine reference (plus the bright patch): it costs (fine)² per texel")
    parser.add_argument("--quick", action="store_true", help="skip the fine reference and the window sweep")
    parser.add_argument("--skip-windows", action="store_true", help="skip the window sweep and mc")
    parser.add_argument("--speed", action="store_true", help="only mc against sh at order 64, and sh's order sweep")
    parser.add_argument("--transforms", action="store_true", help="only ducc0 against SHTns on sht's syntheses")
    parser.add_argument("--speed-figure", type=Path, metavar="PNG",
                        help="only sh's time over its orders and mc's, per asset, plotted to PNG")
    parser.add_argument("--mc-figure", type=Path, metavar="PNG",
                        help="only mc's maps on grids and at every texel side by side (night), written to PNG")
    args = parser.parse_args()
    if args.speed_figure:
        speed_figure(args.speed_figure, args.assets.split(","))
        return
    if args.mc_figure:
        mc_figure(args.mc_figure)
        return
    if args.transforms:
        transforms(args.assets.split(","))
        return
    if args.speed:
        speed(args.assets.split(","), args.texels)
        return
    header = "  ".join(f"{f's={s}':>12}" for s in EXPONENTS)
    worst = {"sht": [0.0, 0.0], "sht fine": [0.0, 0.0], "sht equirect fine": [0.0, 0.0]}
    for name in args.assets.split(","):
        source = read_hdr(assets_dir() / "envmaps" / f"{name}.exr")
        env = to_layout(source, "anglemap", 512)
        bake(env, EXPONENTS, "sht")  # warm: the per-size caches (texel locations, normalisers, lookups)
        peer(env, EXPONENTS)
        sht_s, sht_bake = timed_best(3, lambda: bake(env, EXPONENTS, "sht"))
        peer_s, peer_maps = timed_best(3, lambda: peer(env, EXPONENTS))
        fast_s = best_of(1, lambda: bake(env, EXPONENTS, "fast"))
        print(f"\n{name}: sht {sht_s:.3f} s, peer (ducc0 L=255 script) {peer_s:.3f} s, fast {fast_s:.3f} s; "
              f"peer/sht = {peer_s / sht_s:.2f}x, fast/sht = {fast_s / sht_s:.2f}x")
        texels = reference_texels(env, args.texels)
        directions = anglemap_directions(512).reshape(-1, 3)[texels]
        reference = lobe_average_at(env, EXPONENTS, directions)
        print(f"  {'mean/max % at ' + str(len(texels)) + ' texels':<30}{header}")
        e = errors(reference, sht_bake.maps, texels)
        print(f"  {'sht vs brute force 512²':<30}{row(e)}")
        worst["sht"] = [max(worst["sht"][0], max(x.mean_percent for x in e)), max(worst["sht"][1], max(x.max_percent for x in e))]
        print(f"  {'peer vs brute force 512²':<30}{row(errors(reference, peer_maps, texels))}")
        # sht from the equirect itself (its own 1024 x 512 texels): nothing resampled before the sums.
        src_s, src_maps = timed_best(3, lambda: sht_maps_from_source(source, 512, EXPONENTS))
        e = errors(reference, src_maps, texels)
        print(f"  {'sht from equirect vs 512²':<30}{row(e)}   ({src_s:.3f} s; peer/this = {peer_s / src_s:.2f}x)")
        if not args.quick:
            fine = to_layout(source, "anglemap", args.fine)
            start = time.perf_counter()
            fine_texels = reference_texels(env, args.fine_texels)
            fine_ref = brute_force(fine, EXPONENTS, anglemap_directions(512).reshape(-1, 3)[fine_texels])
            # The two references' own gap: the same sums over the 512² angle map, at the fine reference's texels.
            coarse = brute_force(env, EXPONENTS, anglemap_directions(512).reshape(-1, 3)[fine_texels])
            gap = [map_error(fine_ref[:, k], coarse[:, k]) for k in range(len(EXPONENTS))]
            print(f"  {f'brute force 512² vs {args.fine}²':<30}{row(gap)}")
            e = errors(fine_ref, sht_bake.maps, fine_texels)
            print(f"  {f'sht vs brute force {args.fine}²':<30}{row(e)}   (at {len(fine_texels)} texels; "
                  f"reference {time.perf_counter() - start:.0f} s)")
            worst["sht fine"] = [max(worst["sht fine"][0], max(x.mean_percent for x in e)),
                                 max(worst["sht fine"][1], max(x.max_percent for x in e))]
            print(f"  {f'peer vs brute force {args.fine}²':<30}{row(errors(fine_ref, peer_maps, fine_texels))}")
            e = errors(fine_ref, src_maps, fine_texels)
            print(f"  {f'sht equirect vs {args.fine}²':<30}{row(e)}")
            sh_src = bake(env, EXPONENTS, "sh", MapParameters(sh_order=256), source=source).maps  # (its own texels)
            print(f"  {f'sh 256 equirect vs {args.fine}²':<30}{row(errors(fine_ref, sh_src, fine_texels))}")
            worst["sht equirect fine"] = [max(worst["sht equirect fine"][0], max(x.mean_percent for x in e)),
                                          max(worst["sht equirect fine"][1], max(x.max_percent for x in e))]

        # sh at order 256 against what ducc0 itself needs for one analysis and nine syntheses of its grid.
        params = MapParameters(sh_order=256)
        sh_s = best_of(3, lambda: bake(env, EXPONENTS, "sh", params))
        n_theta, n_phi = synthesis_grid_size(256)
        grid = np.random.default_rng(0).random((1, n_theta, n_phi))

        def ducc_alone():
            alms = [SHT.analysis_2d(map=grid, spin=0, lmax=255, geometry="CC", nthreads=0) for _ in range(3)]
            for _ in EXPONENTS:
                for a in alms:
                    SHT.synthesis_2d(alm=a, spin=0, lmax=255, geometry="CC", ntheta=n_theta, nphi=n_phi, nthreads=0)

        ducc_s = best_of(3, ducc_alone)
        print(f"  sh order 256 (coefficients + nine maps): {sh_s:.2f} s; ducc0 alone (3 analyses + 27 syntheses of "
              f"its {n_theta}x{n_phi} grid): {ducc_s:.2f} s; ratio {sh_s / ducc_s:.2f}x")

        if not args.quick and not args.skip_windows:
            orders = [8, 16, 32, 64, 128, 256]
            print(f"  sh mean error % against brute force 512², by window and order {orders}:")
            for window in WINDOWS:
                baked = [bake(env, EXPONENTS, "sh", MapParameters(sh_order=o, sh_window=window)).maps for o in orders]
                means = np.array([[x.mean_percent for x in errors(reference, maps, texels)] for maps in baked])
                # and the relative RMS error (the error's energy), which a window that only grows with order lowers
                rms = np.array([[100 * np.sqrt(np.mean((reference[:, k] - maps[k].reshape(-1, 3)[texels]) ** 2)
                                               / np.mean(reference[:, k] ** 2)) for k in range(len(EXPONENTS))]
                                for maps in baked])
                print(f"    {window:<8} " + "  ".join(f"s={s}: " + "/".join(f"{v:.3g}" for v in means[:, k])
                                                    for k, s in enumerate(EXPONENTS)))
                for label, figures in (("mean error", means), ("relative RMS error", rms)):
                    not_falling = [s for k, s in enumerate(EXPONENTS) if not np.all(np.diff(figures[:, k]) <= 1e-9)]
                    print(f"    {'':<8} {label} falls monotonically at every exponent: {not not_falling}"
                          + (f" (not at s = {not_falling})" if not_falling else ""))
    print("\nworst over assets and exponents, mean/max %: " + ", ".join(f"{k} {v[0]:.3f}/{v[1]:.2f}" for k, v in worst.items()))


if __name__ == "__main__":
    main()
