"""The maps on the GL path (moderngl), tile by tile, as the thesis bakes them inside the frame loop
(Alg. 4.1/4.2 accurate, with the bounds optimisation as an option; Alg. 4.7 SH maps from a coefficient
texture): a fragment pass per group of up to eight maps, one colour attachment each, restricted to one
tile by the thesis's tileOffset and tileScale. The NumPy methods (accurate.py, sh.py) are the oracles.

Fragment passes rather than compute: a tile is a quad in the maps' own framebuffer, which is how the
thesis bakes them on OpenGL ES 3.0 and what every GL has; on llvmpipe, a compute shader doing the same
sums measured no faster.

Storage: RGBA32F textures with GL's rows bottom-up, the map's t axis, so that tileOffset (in t) is the
thesis's; read back with row 0 at the top.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib import resources

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.gl import create_gl_context
from arsim.lighting.accurate import Tile, check_inputs, tiles
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh import sh_coefficients

MAX_MAPS_PER_PASS = 8  # the colour attachments every GL 4.3 has
MAX_SPANS = 2048  # spans of input texels a draw takes: 16 KiB, the uniform block every GL 4.3 allows
PASS_INPUTS = 32768  # input texels a draw sums at most (with MAX_SPANS, loop iterations below 65 535)
FOLD_TERMS = 64  # input texels the accurate shader sums plainly before adding them into its compensated sums
COEFFICIENT_ROW = 1024  # texels per row of the SH coefficient texture


def _shader(name: str) -> str:
    return resources.files("arsim.lighting").joinpath("shaders", name).read_text(encoding="utf-8")


def tile_offset_scale(tile: Tile, n: int) -> tuple[tuple[float, float], float]:
    """The thesis's tileOffset (s, t of the tile's lower-left corner) and tileScale (its side over N)."""
    return (tile.col0 / n, 1.0 - (tile.row0 + tile.size) / n), tile.size / n


class GLBaker:
    """Maps of an N x N angle map baked on the GL path one tile at a time; read() gives them as
    (E, N, N, 3) float32 with untouched tiles 0 (black, the thesis's progress display). Subclasses give
    the fragment shader and what a pass needs."""

    shader = ""

    def __init__(self, env: np.ndarray, exponents: Sequence[float], ctx=None, defines: Sequence[str] = ()):
        check_inputs(env, exponents)
        self.ctx = ctx or create_gl_context()
        self.n = n = env.shape[0]
        self.exponents = [float(s) for s in exponents]
        self.inside = anglemap_disk_mask(n)
        # Output directions computed in float64 and stored in float32: the shaders do no trigonometry to
        # find them.
        self.out_dirs = anglemap_directions(n)
        directions = np.concatenate([self.out_dirs, self.inside[..., None]], axis=-1)[::-1]  # GL rows: t upwards
        self.directions = self.ctx.texture((n, n), 4, np.ascontiguousarray(directions, dtype="f4").tobytes(), dtype="f4")
        self.maps = [self.ctx.texture((n, n), 4, dtype="f4") for _ in self.exponents]
        for texture in self.maps:  # (shown filtered in the progress display: no wrapping at its edges)
            texture.repeat_x = texture.repeat_y = False
        self.passes = []
        for start in range(0, len(self.exponents), MAX_MAPS_PER_PASS):
            group = list(range(start, min(start + MAX_MAPS_PER_PASS, len(self.exponents))))
            header = "#version 430\n" + "".join(f"#define {d}\n" for d in (f"MAPS {len(group)}", *defines))
            program = self.ctx.program(vertex_shader="#version 430\n" + _shader("bake_tile.vert"),
                                       fragment_shader=header + _shader(self.shader))
            fbo = self.ctx.framebuffer([self.maps[k] for k in group])
            fbo.clear(0.0, 0.0, 0.0, 0.0)  # untouched tiles stay black
            self.passes.append((group, program, self.ctx.vertex_array(program, []), fbo))
        self.resources = [self.directions, *self.maps]

    # Whether a tile's input terms can be summed in ranges over several calls (bake_range's first, count).
    splits_inputs = False

    def inputs(self, tile: Tile) -> int:
        """How many input terms each texel of the tile sums: what the time of a pass is proportional to."""
        raise NotImplementedError

    def bake_range(self, tile: Tile, first: int = 0, count: int | None = None, last: bool = True) -> None:
        """Add the tile's sums over input terms first .. first+count-1 (all: None) and, with last, make
        its maps' texels from them."""
        raise NotImplementedError

    def bake_tile(self, tile: Tile) -> None:
        """Compute every map's texels in the tile."""
        self.bake_range(tile)

    def _draw(self, tile: Tile, program, vao, fbo) -> None:
        """One pass's quad over the tile, placed by the thesis's tileOffset and tileScale."""
        (s0, t0), scale = tile_offset_scale(tile, self.n)
        program["tile_offset"].value, program["tile_scale"].value = (s0, t0), scale
        fbo.use()
        fbo.viewport = (0, 0, self.n, self.n)
        vao.render(vertices=6)

    def bake_all(self, tile_size: int | None = None) -> np.ndarray:
        for tile in tiles(self.n, tile_size or self.n):
            self.bake_tile(tile)
        return self.read()

    def read(self) -> np.ndarray:
        """(E, N, N, 3) float32, row 0 at the top; texels outside the disk and unbaked tiles 0."""
        out = np.empty((len(self.maps), self.n, self.n, 3), np.float32)
        for k, texture in enumerate(self.maps):
            out[k] = np.frombuffer(texture.read(), dtype=np.float32).reshape(self.n, self.n, 4)[::-1, :, :3]
        return out

    def release(self) -> None:
        for obj in self.resources:
            obj.release()
        for _, program, vao, fbo in self.passes:
            vao.release()
            fbo.release()
            program.release()


class GLAccurateBaker(GLBaker):
    """Alg. 4.1/4.2: the accurate maps, or with bounds_threshold the bounds-optimised ones (lobe values
    below it dropped). A pass visits only the input texels that can reach the tile: within 90 degrees of
    one of its texels (accurate: the others give f = 0), or within the cone of the widest kept lobe
    (bounds). A tile may be summed in ranges of those over several calls (bake_range), its sums added by
    blending, and divided when the last range is in."""

    shader = "bake_accurate.frag"
    splits_inputs = True

    def __init__(self, env: np.ndarray, exponents: Sequence[float], ctx=None, bounds_threshold: float | None = None):
        super().__init__(env, exponents, ctx, [f"MAX_SPANS {MAX_SPANS}", f"FOLD_TERMS {FOLD_TERMS}",
                                               *(["BOUNDS"] if bounds_threshold is not None else [])])
        self.threshold = bounds_threshold
        # The widest cone around a tile's texels whose input texels add anything: the hemisphere, or the
        # smallest exponent's lobe down to the threshold.
        self.cone = np.pi / 2 if bounds_threshold is None else float(np.arccos(bounds_threshold ** (1.0 / min(self.exponents))))
        weights = anglemap_solid_angles(self.n)[self.inside]
        self.in_dirs = anglemap_directions(self.n)[self.inside]  # float64, for the tiles' spans
        probe = np.concatenate([self.in_dirs, weights[:, None]], axis=1).astype("f4")
        radiance = np.concatenate([env[self.inside, :3].astype(np.float64) * weights[:, None],
                                   np.zeros((len(weights), 1))], axis=1).astype("f4")
        self.count = len(weights)
        self.probe = self.ctx.buffer(probe.tobytes())
        self.radiance = self.ctx.buffer(radiance.tobytes())
        self.span_lists: dict[Tile, np.ndarray] = {}
        self.spans = self.ctx.buffer(reserve=16 * (MAX_SPANS // 2))
        self.sums = [self.ctx.texture((self.n, self.n), 4, dtype="f4") for _ in self.exponents]
        self.resolvers = []
        for group, program, _, _ in self.passes:
            program["exponents"].write(np.array([self.exponents[k] for k in group], dtype="f4").tobytes())  # (a one-map pass: a float, not a list)
            program["Spans"].binding = 0
            if "threshold" in program:
                program["threshold"].value = bounds_threshold
            sums_fbo = self.ctx.framebuffer([self.sums[k] for k in group])
            sums_fbo.clear(0.0, 0.0, 0.0, 0.0)
            header = f"#version 430\n#define MAPS {len(group)}\n"
            resolver = self.ctx.program(vertex_shader="#version 430\n" + _shader("bake_tile.vert"),
                                        fragment_shader=header + _shader("bake_resolve.frag"))
            resolver["sums"].write(np.arange(len(group), dtype="i4").tobytes())  # (as bytes: an array of one takes no list)
            self.resolvers.append((resolver, self.ctx.vertex_array(resolver, []), sums_fbo))
        self.resources += [self.probe, self.radiance, *self.sums]

    def inputs(self, tile: Tile) -> int:
        """How many input texels a pass over this tile visits."""
        spans = self._tile_spans(tile)
        return int((spans[:, 1] - spans[:, 0]).sum())

    def _tile_spans(self, tile: Tile) -> np.ndarray:
        """(R, 2) [start, end) of the input texels within the cone around any of the tile's directions, in
        index order (the order of the NumPy reference's sums)."""
        if tile not in self.span_lists:
            rr = slice(tile.row0, tile.row0 + tile.size)
            cc = slice(tile.col0, tile.col0 + tile.size)
            block = self.out_dirs[rr, cc][self.inside[rr, cc]]
            spans = np.zeros((0, 2), dtype=np.int64)
            if len(block):
                centre = block.mean(axis=0)
                centre /= np.linalg.norm(centre)
                spread = float(np.arccos(np.clip(block @ centre, -1.0, 1.0)).max())
                # (a margin for the float32 dot products on the GL side: a texel at the cone's edge adds 0)
                near = self.in_dirs @ centre >= np.cos(min(np.pi, self.cone + spread)) - 1e-6
                edges = np.flatnonzero(np.diff(np.concatenate([[0], near.astype(np.int8), [0]])))
                spans = edges.reshape(-1, 2)
            self.span_lists[tile] = spans
        return self.span_lists[tile]

    def _range_spans(self, tile: Tile, first: int, count: int) -> np.ndarray:
        """The tile's spans cut to its visited texels first .. first+count-1, at most MAX_SPANS of them
        (the closest merged: the texels between add nothing, as f = 0 or below the threshold there)."""
        spans = self._tile_spans(tile)
        lengths = spans[:, 1] - spans[:, 0]
        ends = np.cumsum(lengths)
        starts = ends - lengths
        keep = (ends > first) & (starts < first + count)
        cut = spans[keep].copy()
        cut[:, 0] += np.maximum(first - starts[keep], 0)
        cut[:, 1] -= np.maximum(ends[keep] - (first + count), 0)
        while len(cut) > MAX_SPANS:
            gaps = cut[1:, 0] - cut[:-1, 1]
            join = np.zeros(len(cut), bool)
            join[1:][gaps <= np.partition(gaps, len(cut) - MAX_SPANS - 1)[len(cut) - MAX_SPANS - 1]] = True
            group = np.cumsum(~join) - 1
            merged = np.empty((group[-1] + 1, 2), dtype=cut.dtype)
            merged[:, 0] = cut[~join, 0]
            merged[:, 1] = np.maximum.reduceat(cut[:, 1], np.flatnonzero(~join))
            cut = merged
        return cut

    def bake_range(self, tile: Tile, first: int = 0, count: int | None = None, last: bool = True) -> None:
        """Add the sums over the visited texels first .. first+count-1 (all: None) to the tile's, and with
        last, divide them into the maps."""
        count = self.inputs(tile) - first if count is None else count
        self.probe.bind_to_storage_buffer(0)
        self.radiance.bind_to_storage_buffer(1)
        self.directions.use(0)
        self.ctx.enable(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.ONE, self.ctx.ONE
        # A draw per PASS_INPUTS of the range: llvmpipe ends a shader's loops after 65 535 iterations in
        # all (a 512² probe has 206 000 input texels); the draws' sums add by blending.
        for start in range(first, first + count, PASS_INPUTS) if tile.size > 0 else [first]:
            spans = (self._range_spans(tile, start, min(PASS_INPUTS, first + count - start)) if tile.size > 0
                     else np.zeros((0, 2), np.int64))
            # A buffer of its own for each draw: llvmpipe lets a write into a buffer that queued draws
            # still read reach them (a tiled bake then mixed the tiles' spans).
            # (The whole block's size: a GL may refuse a draw whose uniform buffer is smaller.)
            block = np.zeros((MAX_SPANS, 2), dtype="i4")
            block[:len(spans)] = spans
            self.spans.release()
            self.spans = self.ctx.buffer(block.tobytes())
            self.spans.bind_to_uniform_block(0)
            for (group, program, vao, _), (_, _, sums_fbo) in zip(self.passes, self.resolvers):
                program["directions"].value = 0
                program["span_count"].value = len(spans)
                self._draw(tile, program, vao, sums_fbo)
        self.ctx.disable(self.ctx.BLEND)
        if last:
            for (group, _, _, maps_fbo), (resolver, vao, _) in zip(self.passes, self.resolvers):
                for unit, k in enumerate(group):
                    self.sums[k].use(unit)
                self._draw(tile, resolver, vao, maps_fbo)

    def release(self) -> None:
        self.spans.release()
        for resolver, vao, fbo in self.resolvers:
            vao.release()
            fbo.release()
            resolver.release()
        super().release()


class GLShBaker(GLBaker):
    """Alg. 4.7: SH maps of `order` bands from the coefficients (computed by sh.py unless given), held in
    a coefficient texture, with the Phong lobe's zonal factors per map in a second texture."""

    shader = "bake_sh.frag"

    def __init__(self, env: np.ndarray, exponents: Sequence[float], order: int, ctx=None, coeffs: np.ndarray | None = None):
        super().__init__(env, exponents, ctx)
        self.order = order
        coeffs = sh_coefficients(env, order) if coeffs is None else coeffs
        count = order * order
        rows = -(-count // COEFFICIENT_ROW)
        texels = np.zeros((rows * COEFFICIENT_ROW, 4), np.float32)
        texels[:count, :3] = coeffs[:count, :3]
        self.coefficients = self.ctx.texture((COEFFICIENT_ROW, rows), 4, texels.tobytes(), dtype="f4")
        self.kappas = []
        for group, program, _, _ in self.passes:
            kappa = np.stack([phong_zonal_coefficients(self.exponents[k], order) for k in group]).astype("f4")
            texture = self.ctx.texture((order, len(group)), 1, np.ascontiguousarray(kappa).tobytes(), dtype="f4")
            self.kappas.append(texture)
            program["order"].value = order
        self.resources += [self.coefficients, *self.kappas]

    def inputs(self, tile: Tile) -> int:
        return self.order * self.order

    def bake_range(self, tile: Tile, first: int = 0, count: int | None = None, last: bool = True) -> None:
        """The tile's maps in one call: every SH term of a texel is summed in one pass (no ranges)."""
        if first != 0 or count not in (None, self.inputs(tile)) or not last:
            raise ValueError("SH maps are baked a whole tile at a time")
        self.directions.use(0)
        self.coefficients.use(1)
        for kappas, (group, program, vao, fbo) in zip(self.kappas, self.passes):
            kappas.use(2)
            program["directions"].value, program["coefficients"].value, program["kappas"].value = 0, 1, 2
            self._draw(tile, program, vao, fbo)


def gl_accurate_maps(env: np.ndarray, exponents: Sequence[float], tile_size: int | None = None, ctx=None,
                     bounds_threshold: float | None = None) -> np.ndarray:
    """The accurate (or bounds) maps baked on the GL path, tile by tile (tile_size None: one tile)."""
    baker = GLAccurateBaker(env, exponents, ctx, bounds_threshold)
    maps = baker.bake_all(tile_size)
    baker.release()
    return maps


def gl_sh_maps(env: np.ndarray, exponents: Sequence[float], order: int, tile_size: int | None = None, ctx=None,
               coeffs: np.ndarray | None = None) -> np.ndarray:
    """Alg. 4.7's SH maps baked on the GL path, tile by tile (tile_size None: one tile)."""
    baker = GLShBaker(env, exponents, order, ctx, coeffs)
    maps = baker.bake_all(tile_size)
    baker.release()
    return maps
