"""A map set: one method's irradiance and reflection maps of one light, every exponent, with where they came
from. What a bake makes, what `arsim bake` writes and reads, and what the renderer lights objects with."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MapSet:
    method: str  # the map method (lighting.methods.METHODS)
    maps: dict[float, np.ndarray] = field(repr=False)  # exponent -> (N, N, 3) float32 angle map; 1 the irradiance map
    source: str = ""  # what they were computed from (a probe file, "captured", "truth")

    @classmethod
    def of(cls, method: str, exponents: Sequence[float], arrays, source: str = "") -> MapSet:
        """From a bake's (E, N, N, 3) maps (or a list of them) in the order of exponents."""
        return cls(method, {float(s): m for s, m in zip(exponents, arrays)}, source)

    @property
    def exponents(self) -> tuple[float, ...]:
        return tuple(sorted(self.maps))

    @property
    def size(self) -> int:
        return next(iter(self.maps.values())).shape[0]

    def __getitem__(self, exponent: float) -> np.ndarray:
        return self.maps[float(exponent)]

    def __contains__(self, exponent: float) -> bool:
        return float(exponent) in self.maps

    def merged(self, other: MapSet) -> MapSet:
        """This set with another of the same method's maps added (theirs where both have an exponent)."""
        sources = ", ".join(s for s in dict.fromkeys((self.source, other.source)) if s)
        return MapSet(self.method, {**self.maps, **other.maps}, sources)
