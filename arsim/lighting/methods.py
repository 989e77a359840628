"""The map methods by name (METHODS: the only list of them; the scenario's schema, the frame loop's baker
and the command line take their choices from it), their parameters, and a timed bake of several exponents at
once. A new method is one entry here: its functions, the parameters it reads, whether it has a GL path and
whether it can bake inside the frame loop (README: Adding a map method).

Every method takes an N x N angle map and Phong exponents and returns one float32 angle map per
exponent (E, N, N, 3): s = 1 is the irradiance map (E / pi), s > 1 reflection maps (README: Conventions).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from arsim.core.errors import ArsimError
from arsim.lighting.accurate import DEFAULT_BOUNDS_THRESHOLD, accurate_maps, check_inputs
from arsim.lighting.fast import fast_coefficients, fast_maps, order_for_exponent
from arsim.lighting.mc import check_samples, mc_maps
from arsim.lighting.mipmap import mipmap_maps
from arsim.lighting.sh import GRID_MAX_ORDER, MAX_ORDER, RINGS_MAX_ORDER, WINDOWS, sh_coefficients, sh_maps
from arsim.lighting.sht import bands_for_exponent, equirect_texel_sums, sht_map, sht_maps_from_source, sht_prepare

DEFAULT_EXPONENTS = (1, 2, 10, 20, 40, 80, 160, 240, 320, 640, 1280)
SH_ORDER = 35  # sh: bands 0..SH_ORDER-1, the thesis's order in its figures


@dataclass(frozen=True)
class MapParameters:
    """What the methods can be tuned with (each uses only its own)."""

    sh_order: int = SH_ORDER  # sh: bands 0..sh_order-1
    sh_faithful: bool = False  # sh: evaluate Y_lm as Alg. 2.5/2.6 (factorials in double)
    sh_window: str = "none"  # sh: plain truncation, or a window against ringing (sh.WINDOWS)
    samples: int = 64  # mc: importance samples per point (a texel, or a point of the lobe's grid)
    seed: int = 0  # mc
    mc_texels: bool = False  # mc: every lobe estimated at every texel instead of on its grid (mc.lobe_grid)
    bounds_threshold: float = DEFAULT_BOUNDS_THRESHOLD  # bounds: smallest lobe value kept

    def check(self) -> None:
        if not 1 <= self.sh_order <= MAX_ORDER:
            raise ArsimError(f"SH order {self.sh_order} is out of range: give 1 to {MAX_ORDER}")
        if self.sh_faithful and self.sh_order > GRID_MAX_ORDER:
            raise ArsimError(f"SH order {self.sh_order} is out of range for --sh-faithful: give 1 to {GRID_MAX_ORDER} "
                             "(its factorials lose every band from 86 anyway)")
        if self.sh_window not in WINDOWS:
            raise ArsimError(f"SH window '{self.sh_window}' is unknown: give one of {', '.join(WINDOWS)}")
        if self.samples < 1:
            raise ArsimError(f"sample count {self.samples} is out of range: give at least 1")
        check_samples(self.samples)
        if self.seed < 0:
            raise ArsimError(f"seed {self.seed} is negative: give 0 or more")
        if not 0 < self.bounds_threshold < 1:
            raise ArsimError(f"bounds threshold {self.bounds_threshold} is out of range: give a value in (0, 1)")


@dataclass(frozen=True)
class Method:
    """A map method: `prepare` does the work all maps share (SH coefficients, say) once, `map` makes the
    map of one exponent from it. Splitting them lets a bake report the time of every map."""

    name: str
    summary: str
    prepare: Callable[[np.ndarray, Sequence[float], MapParameters], object]
    map: Callable[[np.ndarray, object, float, MapParameters], np.ndarray]
    parameters: tuple[str, ...] = ()  # the MapParameters fields it reads (bake.json records those)
    gl: bool = False  # a GL bake (gl_bake.py), held to this NumPy oracle within 1e-3 relative by the tests
    in_loop: bool = False  # can bake tile by tile inside the frame loop (render/baking.py)
    # (env, source, exponents, params) -> the maps summed over a larger equirect source's own texels, or None
    # where the method sums the map's texels only (sums_source says when it is used)
    from_source: Callable[[np.ndarray, np.ndarray, Sequence[float], MapParameters], np.ndarray] | None = None
    source_unless: str = ""  # a MapParameters flag that, set, keeps the method on the map's texels


def _sh_prepare(env, exponents, p):
    """The coefficients, and up to RINGS_MAX_ORDER every map as well: the ring path evaluates them all in one
    pass over the rings (sh.sh_maps), in about half the time map by map (all shared time, as mc's)."""
    coeffs = sh_coefficients(env, p.sh_order, p.sh_faithful)
    if p.sh_faithful or p.sh_order > RINGS_MAX_ORDER:
        return coeffs, None
    return coeffs, dict(zip(map(float, exponents), sh_maps(env, exponents, p.sh_order, coeffs=coeffs, window=p.sh_window)))


def _sh_map(env, prepared, s, p):
    coeffs, maps = prepared
    if maps is not None:
        return maps[float(s)]
    return sh_maps(env, [s], p.sh_order, p.sh_faithful, coeffs=coeffs, window=p.sh_window)[0]


def _sh_from_source(env, source, exponents, p):
    return sh_maps(env, exponents, p.sh_order, coeffs=equirect_texel_sums(source, p.sh_order), window=p.sh_window)


def _fast_prepare(env, exponents, p):
    return fast_coefficients(env, exponents)


METHODS = {
    m.name: m
    for m in (
        Method("accurate", "brute-force sum over every texel (Alg. 4.1/4.2), float64: the reference",
               lambda env, ex, p: None, lambda env, _, s, p: accurate_maps(env, [s])[0], gl=True, in_loop=True),
        Method("bounds", "the accurate sum over the cone where the lobe exceeds a threshold (section 6.2.2)",
               lambda env, ex, p: None,
               lambda env, _, s, p: accurate_maps(env, [s], bounds_threshold=p.bounds_threshold)[0],
               ("bounds_threshold",), gl=True, in_loop=True),
        Method("fast", "exact texel sums through SH of the order each lobe needs (about a second at 512²)",
               _fast_prepare, lambda env, c, s, p: fast_maps(env, [s], coeffs=c)[0]),
        Method("mipmap", "trilinear lookup in a 2x2-box MIP chain at the level of eq. 4.2/4.3 (Alg. 4.3)",
               lambda env, ex, p: None, lambda env, _, s, p: mipmap_maps(env, [s])[0]),
        Method("sh", "spherical harmonics of --sh-order bands convolved with the Phong lobe (Alg. 4.4-4.7)",
               _sh_prepare, _sh_map,
               ("sh_order", "sh_faithful", "sh_window"), in_loop=True, from_source=_sh_from_source,
               source_unless="sh_faithful"),  # (the thesis's formulas walk the angle map's rings)
        Method("sht", "exact texel sums and per-exponent syntheses through ducc0's fast SH transforms (fastest)",
               lambda env, ex, p: sht_prepare(env, ex), lambda env, c, s, p: sht_map(env, c, s),
               from_source=lambda env, source, ex, p: sht_maps_from_source(source, env.shape[0], ex)),
        # mc bakes every exponent in one pass over the texels (its frames and chain shared): all shared time.
        Method("mc", "Monte Carlo importance sampling with MIP-filtered samples (Colbert and Krivanek)",
               lambda env, ex, p: dict(zip(map(float, ex), mc_maps(env, ex, p.samples, p.seed, grids=not p.mc_texels))),
               lambda env, maps, s, p: maps[s], ("samples", "seed", "mc_texels")),
    )
}


def method(name: str) -> Method:
    if name not in METHODS:
        raise ArsimError(f"map method '{name}' is unknown; use one of {', '.join(METHODS)}")
    return METHODS[name]


def parameters_used(name: str, params: MapParameters) -> dict:
    """The parameters that matter for a method (for bake.json and reports)."""
    return {k: v for k, v in asdict(params).items() if k in method(name).parameters}


def sh_orders_used(name: str, params: MapParameters, exponents: Sequence[float]) -> list[int] | None:
    """The SH order (bands 0..order-1) each exponent's map is made with, for the methods that go through SH:
    sh's --sh-order for every map, fast's and sht's the order each lobe needs; None for the others."""
    if name == "sh":
        return [params.sh_order] * len(exponents)
    if name == "fast":
        return [order_for_exponent(s) for s in exponents]
    if name == "sht":
        return [bands_for_exponent(float(s)) for s in exponents]
    return None


@dataclass(frozen=True)
class BakeResult:
    maps: np.ndarray  # (E, N, N, 3) float32
    seconds_shared: float  # work all maps share (SH coefficients)
    seconds_per_map: tuple[float, ...]  # one per exponent
    computed_on: str = "numpy"  # or "gl: <renderer>"
    summed_over: str = "angle map"  # the texels the lobe averages ran over (sums_source says when not the map's)

    @property
    def seconds_total(self) -> float:
        return self.seconds_shared + sum(self.seconds_per_map)


GL_METHODS = tuple(name for name, m in METHODS.items() if m.gl)
LOOP_METHODS = tuple(name for name, m in METHODS.items() if m.in_loop)  # what the frame loop can bake


def sums_source(name: str, env: np.ndarray, source: np.ndarray | None, params: MapParameters | None = None) -> bool:
    """Whether the method sums the probe's own texels instead of env's: one with a from_source path (unless its
    source_unless flag is set in params), given an equirect source with more texels than the N x N map, which
    resampling to the map would thin out (a small bright source loses or gains energy)."""
    m = method(name)
    return (m.from_source is not None and not (m.source_unless and getattr(params or MapParameters(), m.source_unless))
            and source is not None and source.ndim == 3 and source.shape[1] == 2 * source.shape[0]
            and source.shape[0] * source.shape[1] > env.shape[0] * env.shape[1])


def bake(env: np.ndarray, exponents: Sequence[float], name: str, params: MapParameters | None = None,
         progress: Callable[[int], None] | None = None, gl=None, source: np.ndarray | None = None) -> BakeResult:
    """All maps of one method, timed; progress(k) is called after map k is done. With a moderngl context
    `gl`, the GL_METHODS bake on the GL path (float32), all maps in one pass: its time is all shared.
    source: the probe as read, before it was resampled to env; `sht` and `sh` sum it at its own resolution
    where sums_source says so (all its time shared)."""
    params = params or MapParameters()
    params.check()
    check_inputs(env, exponents)
    m = method(name)
    if sums_source(name, env, source, params):
        start = time.perf_counter()
        maps = m.from_source(env, source, list(exponents), params)
        if progress is not None:
            progress(len(exponents))
        if not np.isfinite(maps).all():
            raise ArsimError(f"method {name} produced non-finite values; please report this with the input")
        h, w = source.shape[:2]
        return BakeResult(maps, time.perf_counter() - start, (0.0,) * len(exponents),
                          summed_over=f"equirect {w}x{h} at its own resolution")
    if gl is not None and name in GL_METHODS:
        from arsim.lighting.gl_bake import gl_accurate_maps

        start = time.perf_counter()
        maps = gl_accurate_maps(env, exponents, ctx=gl, bounds_threshold=params.bounds_threshold if name == "bounds" else None)
        if progress is not None:
            progress(len(exponents))
        return BakeResult(maps, time.perf_counter() - start, (0.0,) * len(exponents), f"gl: {gl.info['GL_RENDERER']}")
    start = time.perf_counter()
    shared = m.prepare(env, list(exponents), params)
    shared_s = time.perf_counter() - start
    maps = np.zeros((len(exponents),) + env.shape[:2] + (3,), dtype=np.float32)
    per_map = []
    for k, s in enumerate(exponents):
        start = time.perf_counter()
        maps[k] = m.map(env, shared, float(s), params)
        per_map.append(time.perf_counter() - start)
        if progress is not None:
            progress(k + 1)
    if not np.isfinite(maps).all():  # never hand out a NaN or Inf, whatever the method did
        raise ArsimError(f"method {name} produced non-finite values; please report this with the input")
    return BakeResult(maps, shared_s, tuple(per_map))
