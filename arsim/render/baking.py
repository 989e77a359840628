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
from arsim.lighting.accurate import DEFAULT_BOUNDS_THRESHOLD, Tile, tiles
from arsim.lighting.gl_bake import GLAccurateBaker, GLShBaker

BAKE_METHODS = ("accurate", "bounds", "sh")
AUTO_UNIT = 16  # the tile side `auto` schedules in (or the map's side), split where needed
AUTO_FIRST = 4  # auto's first piece, which measures the time per unit of work, is split down to this side
# The smallest tile auto splits down to: llvmpipe runs fragment shaders on 4 x 4 blocks (and GPUs on 2 x 2
# quads in warps of 32 or 64), so a smaller tile costs as much as a block: 1 x 1 tiles made a 128² bake
# 16 times slower.
BLOCK = 4
AUTO_MIN = BLOCK
# Auto sums an accurate (or bounds) tile's input texels in ranges over several frames, halved down to this
# many.
MIN_RANGE = 256
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
    sh_order: int = 35
    bounds_threshold: float = DEFAULT_BOUNDS_THRESHOLD

    def check(self, n: int) -> None:
        if self.method not in BAKE_METHODS:
            raise ArsimError(f"bake method '{self.method}' cannot run in the frame loop; use one of {', '.join(BAKE_METHODS)}")
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
        self.gl_ms_total = 0.0
        self.last_gl_ms = 0.0  # the GL time of the last step's tiles
        self.works: dict = {}

    def warm_up(self) -> None:
        """Draw the bake passes over an empty tile: their shaders' machine code is compiled then."""
        self.gl.bake_tile(Tile(0, 0, 0))

    @property
    def done(self) -> bool:
        return not self.queue

    @property
    def progress(self) -> float:
        """The share of the disk's texels baked."""
        return 1.0 if self.done else self.texels_done / self.texels_total

    def _texels(self, tile) -> int:
        return int(self.gl.inside[tile.row0:tile.row0 + tile.size, tile.col0:tile.col0 + tile.size].sum())

    def _shaded(self, tile) -> int:
        """The texels the GL shades for a tile: every texel of each 4 x 4 block that holds a disk texel."""
        inside = self.gl.inside[tile.row0:tile.row0 + tile.size, tile.col0:tile.col0 + tile.size]
        b = max(min(BLOCK, tile.size), 1)
        blocks = inside.reshape(inside.shape[0] // b, b, inside.shape[1] // b, b).any(axis=(1, 3))
        return int(blocks.sum()) * b * b

    def _work(self, piece: Piece) -> float:
        """A piece's work in units the GL time is proportional to: the texels shaded times the input terms
        each sums."""
        if piece not in self.works:
            count = self.gl.inputs(piece.tile) if piece.count is None else piece.count
            self.works[piece] = float(self._shaded(piece.tile)) * count
        return self.works[piece]

    def _split(self) -> bool:
        """Split the head of the queue: (accurate and bounds) its input texels into halves down to
        MIN_RANGE, summed over several frames; (SH) a whole tile into its four quadrants (row by row, the
        thesis's order) down to AUTO_MIN; False when it cannot be split. Ranges keep the tile whole: a
        wider tile costs less per texel (a draw's fixed costs and llvmpipe's 4 x 4 blocks)."""
        piece = self.queue[0]
        tile = piece.tile
        if not self.gl.splits_inputs:
            if tile.size <= AUTO_MIN:
                return False
            self.queue.popleft()
            half = tile.size // 2
            for dr, dc in reversed([(0, 0), (0, half), (half, 0), (half, half)]):
                self.queue.appendleft(Piece(Tile(tile.row0 + dr, tile.col0 + dc, half)))
            return True
        count = self.gl.inputs(tile) - piece.first if piece.count is None else piece.count
        if count <= MIN_RANGE:
            return False
        self.queue.popleft()
        half = count // 2
        self.queue.appendleft(Piece(tile, piece.first + half, count - half, piece.last))
        self.queue.appendleft(Piece(tile, piece.first, half, False))
        return True

    def _auto_batch(self, available_ms: float) -> list:
        """The pieces predicted to fit: from the head of the queue, splitting the head while even it
        alone would not fit, so that the work per frame follows the time left however costly a texel is."""
        batch, spent = [], 0.0
        if not self.cost_per_work:  # nothing measured yet: a small piece, to measure
            while self.queue[0].tile.size > AUTO_FIRST and self._split():
                pass
            return [self.queue.popleft()]
        cost = max(self.cost_per_work) * AUTO_SAFETY
        while self.queue:
            predicted = self._work(self.queue[0]) * cost + TILE_OVERHEAD_MS
            if spent + predicted <= available_ms:
                batch.append(self.queue.popleft())
                spent += predicted
            elif batch or not self._split():
                break
        return batch

    def step(self, available_ms: float) -> int:
        """Bake the next tile (fixed size), or the pieces predicted to fit in available_ms (auto); returns
        how many."""
        self.last_gl_ms = 0.0
        if self.done:
            return 0
        if self.settings.tile is None:
            batch = self._auto_batch(available_ms)
            if not batch:
                self.idle_frames += 1
                if self.idle_frames < AUTO_STALL_FRAMES:
                    return 0
                batch = [self.queue.popleft()]  # (the smallest piece by now: the bake must end)
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
        self.last_gl_ms = self.query.elapsed / 1e6
        self.gl_ms_total += self.last_gl_ms
        work = sum(self._work(piece) for piece in batch)
        if work > 0:
            self.cost_per_work.append(max(waited - TILE_OVERHEAD_MS * len(batch), 0.0) / work)
        self.texels_done += sum(self._texels(piece.tile) for piece in batch if piece.last)
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
