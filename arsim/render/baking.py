"""Step 3 of the render loop (thesis 4.1, 5.1 step 3, 5.4): maps baked tile by tile inside the frame
loop on the GL path, so that the app stays interactive while they take seconds to minutes. A fixed tile
size bakes one tile per frame, as the thesis does (64 or 128); `auto` bakes as many small tiles as its
measured GL time per unit of work says fit in what the frame budget leaves. When the last tile is done,
the baked maps replace the ones the objects were lit with meanwhile (the app starts with MIP-mapping).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.gl import query_ms
from arsim.lighting.accurate import DEFAULT_BOUNDS_THRESHOLD, Tile, tiles
from arsim.lighting.gl_bake import GLAccurateBaker, GLShBaker
from arsim.lighting.methods import LOOP_METHODS, SH_ORDER

# The tile side `auto` schedules in (or the map's side). Accurate, 512² probe, eight maps, 500 frames of
# 20 ms on llvmpipe: tiles of 32 baked the most work per frame (16: a draw's fixed costs weigh more; 64:
# a wider tile's pass visits 12 % more input texels).
AUTO_UNIT = 32
AUTO_FIRST = 4  # auto's first piece, which measures the time per unit of work, is split down to this side
# The smallest tile auto splits down to: llvmpipe runs fragment shaders on 4 x 4 blocks (and GPUs on 2 x 2
# quads in warps of 32 or 64), so a smaller tile costs as much as a block: 1 x 1 tiles made a 128² bake
# 16 times slower.
BLOCK = 4
AUTO_MIN = BLOCK
# Auto sums an accurate (or bounds) tile's input texels in ranges over several frames, at least this many
# a frame.
MIN_RANGE = 16
AUTO_SAFETY = 1.25  # predicted cost x this must fit: GL time per unit of work varies from tile to tile
TILE_OVERHEAD_MS = 0.1  # the time a piece's draws cost whatever their size (measured on llvmpipe: 0.05-0.1)
AUTO_STALL_FRAMES = 30  # after this many frames without room for a tile, bake one anyway (the bake must end)


@dataclass(frozen=True)
class Piece:
    """What one bake call does: a tile, and the range of input terms it sums (all: count None); with
    last, the tile's sums are then divided into its maps."""

    tile: Tile
    first: int = 0
    count: int | None = None
    last: bool = True


@dataclass(frozen=True)
class BakeSettings:
    method: str = "accurate"  # accurate | bounds | sh
    tile: int | None = None  # a fixed tile side; None: auto
    sh_order: int = SH_ORDER
    bounds_threshold: float = DEFAULT_BOUNDS_THRESHOLD

    def check(self, n: int) -> None:
        if self.method not in LOOP_METHODS:
            raise ArsimError(f"bake method '{self.method}' cannot run in the frame loop; use one of {', '.join(LOOP_METHODS)}")
        if self.tile is not None and (self.tile < 1 or n % self.tile != 0):
            raise ArsimError(f"tile size {self.tile} does not divide the {n} x {n} maps; give a divisor of {n} "
                             f"(e.g. {', '.join(str(d) for d in (16, 32, 64, 128) if n % d == 0 and d <= n)}) or auto")

    @property
    def label(self) -> str:
        return "auto" if self.tile is None else str(self.tile)


class LoopBaker:
    """The maps of `exponents` from an N x N probe, baked a few tiles per frame."""

    def __init__(self, probe: np.ndarray, exponents, settings: BakeSettings, ctx):
        n = probe.shape[0]
        settings.check(n)
        self.settings, self.exponents, self.ctx = settings, [float(s) for s in exponents], ctx
        if settings.method == "sh":
            self.gl = GLShBaker(probe, self.exponents, settings.sh_order, ctx)
        else:
            threshold = settings.bounds_threshold if settings.method == "bounds" else None
            self.gl = GLAccurateBaker(probe, self.exponents, ctx, threshold)
        self.queue = deque(Piece(tile) for tile in tiles(n, settings.tile or min(AUTO_UNIT, n)))
        self.texels_total, self.texels_done = int(self.gl.inside.sum()), 0
        self.query = ctx.query(time=True)
        self.cost_per_work: deque[float] = deque(maxlen=8)  # measured GL ms per unit of work, recent tiles
        self.idle_frames = 0
        self.gl_ms_total = 0.0  # over the valid timer readings
        # The GL time of the last step's tiles (None: it drew none, or its reading was no time: core.gl.timer_ms),
        # and why its reading was dropped
        self.last_gl_ms: float | None = None
        self.last_gl_dropped: str | None = None
        self.shaded: dict[Tile, int] = {}
        self.work_total, self.work_done = sum(self._work(piece) for piece in self.queue), 0.0

    def warm_up(self) -> None:
        """Draw the bake passes over an empty tile: their shaders' machine code is compiled then."""
        self.gl.bake_tile(Tile(0, 0, 0))

    @property
    def done(self) -> bool:
        return not self.queue

    @property
    def progress(self) -> float:
        """The share of the disk's texels baked (the progress display's)."""
        return 1.0 if self.done else self.texels_done / self.texels_total

    @property
    def work_progress(self) -> float:
        """The share of the bake's work done (texels times the input terms each sums): what the frames
        still to come are proportional to, where texels differ in cost."""
        return 1.0 if self.done else self.work_done / max(self.work_total, 1.0)

    def _texels(self, tile) -> int:
        return int(self.gl.inside[tile.row0:tile.row0 + tile.size, tile.col0:tile.col0 + tile.size].sum())

    def _shaded(self, tile) -> int:
        """The texels the GL shades for a tile: every texel of each 4 x 4 block that holds a disk texel."""
        if tile in self.shaded:
            return self.shaded[tile]
        inside = self.gl.inside[tile.row0:tile.row0 + tile.size, tile.col0:tile.col0 + tile.size]
        b = max(min(BLOCK, tile.size), 1)
        blocks = inside.reshape(inside.shape[0] // b, b, inside.shape[1] // b, b).any(axis=(1, 3))
        self.shaded[tile] = int(blocks.sum()) * b * b
        return self.shaded[tile]

    def _count(self, piece: Piece) -> int:
        """The input terms a piece sums."""
        return self.gl.inputs(piece.tile) - piece.first if piece.count is None else piece.count

    def _work(self, piece: Piece) -> float:
        """A piece's work in units the GL time is proportional to: the texels shaded times the input terms
        each sums."""
        return float(self._shaded(piece.tile)) * self._count(piece)

    def _split_quadrants(self) -> bool:
        """(SH) Split the head of the queue, a whole tile, into its four quadrants (row by row, the
        thesis's order) down to AUTO_MIN; False when it cannot be split."""
        tile = self.queue[0].tile
        if tile.size <= AUTO_MIN:
            return False
        self.queue.popleft()
        half = tile.size // 2
        for dr, dc in reversed([(0, 0), (0, half), (half, 0), (half, half)]):
            self.queue.appendleft(Piece(Tile(tile.row0 + dr, tile.col0 + dc, half)))
        return True

    def _take_inputs(self, count: int) -> Piece:
        """(Accurate, bounds) The head tile's next `count` input terms as a piece; the rest stays queued."""
        head = self.queue.popleft()
        rest = self._count(head) - count
        if rest <= 0:
            return head
        self.queue.appendleft(Piece(head.tile, head.first + count, None if head.count is None else rest, head.last))
        return Piece(head.tile, head.first, count, False)

    def _auto_batch(self, available_ms: float) -> list:
        """The pieces predicted to fit in available_ms. Accurate and bounds: the head tile's input terms
        are cut where the time left ends, so that a frame makes one draw of about the time it has (a
        draw's fixed costs paid once, no time lost to a coarse cut). SH: whole tiles, the head split into
        quadrants while even it alone would not fit."""
        if not self.cost_per_work:  # nothing measured yet: a small piece, to measure
            if self.gl.splits_inputs:
                return [self._take_inputs(MIN_RANGE)]
            while self.queue[0].tile.size > AUTO_FIRST and self._split_quadrants():
                pass
            return [self.queue.popleft()]
        cost = max(self.cost_per_work) * AUTO_SAFETY
        batch, left = [], available_ms
        while self.queue:
            head = self.queue[0]
            predicted = self._work(head) * cost + TILE_OVERHEAD_MS
            if predicted <= left:
                batch.append(self.queue.popleft())
                left -= predicted
                continue
            if self.gl.splits_inputs:
                count = int((left - TILE_OVERHEAD_MS) / (self._shaded(head.tile) * cost))
                if count >= MIN_RANGE:
                    batch.append(self._take_inputs(count))
                break
            if batch or not self._split_quadrants():
                break
        return batch

    def step(self, available_ms: float) -> int:
        """Bake the next tile (fixed size), or the pieces predicted to fit in available_ms (auto); returns
        how many."""
        self.last_gl_ms, self.last_gl_dropped = None, None
        if self.done:
            return 0
        if self.settings.tile is None:
            batch = self._auto_batch(available_ms)
            if not batch:
                self.idle_frames += 1
                if self.idle_frames < AUTO_STALL_FRAMES:
                    return 0
                # (the bake must end)
                batch = [self._take_inputs(MIN_RANGE) if self.gl.splits_inputs else self.queue.popleft()]
            self.idle_frames = 0
        else:
            batch = [self.queue.popleft()]
        self.ctx.finish()
        start = time.perf_counter()
        with self.query:
            for piece in batch:
                self.gl.bake_range(piece.tile, piece.first, piece.count, piece.last)
        self.ctx.finish()
        # The schedule follows the time the render thread waits for the bake, which is what the budget
        # holds: on llvmpipe, a timer query can miss part of a draw spread over its threads.
        waited = 1000 * (time.perf_counter() - start)
        self.last_gl_ms, self.last_gl_dropped = query_ms(self.query)
        self.gl_ms_total += self.last_gl_ms or 0.0
        work = sum(self._work(piece) for piece in batch)
        if work > 0:
            self.cost_per_work.append(max(waited - TILE_OVERHEAD_MS * len(batch), 0.0) / work)
        self.texels_done += sum(self._texels(piece.tile) for piece in batch if piece.last)
        self.work_done += work
        return len(batch)

    def maps(self) -> np.ndarray:
        """(E, N, N, 3) float32: the maps so far (black where no tile is done)."""
        return self.gl.read()

    @property
    def thumbnail(self):
        """The first map's texture (the irradiance map, where s = 1 is baked): the progress display."""
        return self.gl.maps[0]

    def release(self) -> None:
        self.gl.release()
