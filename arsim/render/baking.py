"""Step 3 of the render loop (thesis 4.1, 5.1 step 3, 5.4): maps baked tile by tile inside the frame
loop on the GL path, so that the app stays interactive while they take seconds to minutes. A fixed tile
size bakes one tile per frame, as the thesis does (64 or 128); `auto` bakes as many small tiles as its
measured GL time per unit of work says fit in what the frame budget leaves. When the last tile is done,
the baked maps replace the ones the objects were lit with meanwhile (the app starts with MIP-mapping).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from arsim.core.errors import ArsimError
from arsim.lighting.accurate import DEFAULT_BOUNDS_THRESHOLD, Tile, tiles
from arsim.lighting.gl_bake import GLAccurateBaker, GLShBaker

BAKE_METHODS = ("accurate", "bounds", "sh")
AUTO_UNIT = 16  # the tile side `auto` schedules in (or the map's side), split into quadrants where needed
AUTO_FIRST = 4  # the side of auto's first tile, which measures the GL time per unit of work
AUTO_SAFETY = 1.25  # predicted cost x this must fit: GL time per unit of work varies from tile to tile
TILE_OVERHEAD_MS = 0.1  # GL time a tile's passes cost whatever their size (measured on llvmpipe: 0.05-0.1)
AUTO_STALL_FRAMES = 30  # after this many frames without room for a tile, bake one anyway (the bake must end)


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
        self.queue = deque(tiles(n, settings.tile or min(AUTO_UNIT, n)))
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

    def _work(self, tile) -> float:
        """A tile's work in units the GL time is proportional to: its disk texels, times the input texels
        each visits (accurate), the tile's candidates (bounds), or the SH terms (sh)."""
        if tile not in self.works:
            self.works[tile] = self._count_work(tile)
        return self.works[tile]

    def _count_work(self, tile) -> float:
        texels = float(self._texels(tile))
        if isinstance(self.gl, GLShBaker):
            return texels * self.gl.order ** 2
        if self.gl.threshold is not None:
            return texels * len(self.gl._candidates(tile, [min(self.exponents)]))
        return texels * self.gl.count

    def _split(self) -> None:
        """Replace the head of the queue by its four quadrants (row by row, as the thesis's order)."""
        tile = self.queue.popleft()
        half = tile.size // 2
        for quadrant in reversed([Tile(tile.row0 + dr, tile.col0 + dc, half) for dr in (0, half) for dc in (0, half)]):
            self.queue.appendleft(quadrant)

    def _auto_batch(self, available_ms: float) -> list:
        """The tiles predicted to fit: from the head of the queue, splitting the head into quadrants
        while even it alone would not fit (down to single texels), so that the work per frame follows
        the time left however costly a texel is."""
        batch, spent = [], 0.0
        if not self.cost_per_work:  # nothing measured yet: a small tile, to measure
            while self.queue[0].size > AUTO_FIRST:
                self._split()
            return [self.queue.popleft()]
        cost = max(self.cost_per_work) * AUTO_SAFETY
        while self.queue:
            predicted = self._work(self.queue[0]) * cost + TILE_OVERHEAD_MS
            if spent + predicted <= available_ms:
                batch.append(self.queue.popleft())
                spent += predicted
            elif not batch and self.queue[0].size > 1:
                self._split()
            else:
                break
        return batch

    def step(self, available_ms: float) -> int:
        """Bake the next tile (fixed size), or the tiles predicted to fit in available_ms (auto); returns
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
                batch = [self.queue.popleft()]  # (a single texel by now: the bake must end)
            self.idle_frames = 0
        else:
            batch = [self.queue.popleft()]
        with self.query:
            for tile in batch:
                self.gl.bake_tile(tile)
        self.ctx.finish()
        elapsed = self.query.elapsed / 1e6
        self.last_gl_ms = elapsed
        self.gl_ms_total += elapsed
        work = sum(self._work(tile) for tile in batch)
        if work > 0:
            self.cost_per_work.append(max(elapsed - TILE_OVERHEAD_MS * len(batch), 0.0) / work)
        self.texels_done += sum(self._texels(tile) for tile in batch)
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
