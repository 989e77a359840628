"""The basis functions of irradiance normal mapping (the irradiance-normal-mapping spec, 1.8, and the
normal-mapping-prt spec, 3.1), in tangent space: z along the surface normal, x along the tangent, y
along the bitangent. Every function takes unit directions (..., 3) and gives (..., count).

Where the spec's Cartesian forms disagree with its angle forms, the angle forms (the functions' own
definitions) are followed, and the Gram-matrix tests hold them to orthonormality:
- HSH (1.23-1.32): the shifting theorem, H_l^m = K~ {sqrt2 cos(m phi), sqrt2 sin(-m phi), 1} P_l^|m|(2z - 1)
  with K~ = sqrt((2l+1)(l-|m|)! / (2 pi (l+|m|)!)), without the Condon-Shortley phase as the spec's SH:
  1.23's Cartesian minus, 1.26's factor 2 and square root, and 1.30's sin (for cos) are typos.
- Makhotkin (1.33-1.45): 1.33's Cartesian z is sqrt(z); 1.42's 16(z - 1) is 8(z - 1) (4 (2z - 2)).
- Zernike (1.48): the Cartesian minus is a typo (the angle form is +2/sqrt(pi) cos(phi) sin(theta/2)).
- H-basis (1.53): sqrt(3/(2 pi)) y (the square root closes before y).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from math import factorial, pi, sqrt

import numpy as np

from arsim.core.errors import ArsimError


def _xyz(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = np.asarray(d, dtype=np.float64)
    return d[..., 0], d[..., 1], d[..., 2]


def sh9(d: np.ndarray) -> np.ndarray:
    """Real SH of bands 0-2 (spec eq. 1.9-1.17, no Condon-Shortley phase), in the order l(l+1)+m:
    1, y, z, x, xy, yz, 3z^2-1, zx, x^2-y^2."""
    x, y, z = _xyz(d)
    c0, c1, c2, c3 = 0.5 / sqrt(pi), 0.5 * sqrt(3 / pi), 0.5 * sqrt(15 / pi), 0.25 * sqrt(5 / pi)
    return np.stack([np.full_like(x, c0), c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z, c3 * (3 * z * z - 1),
                     c2 * z * x, 0.5 * c2 * (x * x - y * y)], axis=-1)


HL2_VECTORS = np.array([[-1 / sqrt(6), -1 / sqrt(2), 1 / sqrt(3)],
                        [-1 / sqrt(6), 1 / sqrt(2), 1 / sqrt(3)],
                        [sqrt(2 / 3), 0.0, 1 / sqrt(3)]])  # eq. 1.18-1.20


def hl2(d: np.ndarray) -> np.ndarray:
    """Half-Life 2 basis (eq. 1.21): sqrt(3 / (2 pi)) n . h_i, orthonormal over the hemisphere."""
    return sqrt(3 / (2 * pi)) * np.asarray(d, dtype=np.float64) @ HL2_VECTORS.T


def h_basis(d: np.ndarray) -> np.ndarray:
    """H-basis (eq. 1.52-1.57): H1..H6."""
    x, y, z = _xyz(d)
    a, b = sqrt(3 / (2 * pi)), sqrt(15 / (2 * pi))
    return np.stack([np.full_like(x, 1 / sqrt(2 * pi)), a * y, a * (2 * z - 1), a * x, b * x * y,
                     0.5 * b * (x * x - y * y)], axis=-1)


def modified_h_basis(d: np.ndarray) -> np.ndarray:
    """Modified H-basis (eq. 1.58): H3 replaced by sqrt(3 / (2 pi)) (1 - z), so that H1 alone is the
    light map (the others vanish for n = (0, 0, 1)); not orthogonal (H1 . H3mod = sqrt(3) / 2)."""
    values = h_basis(d)
    values[..., 2] = sqrt(3 / (2 * pi)) * (1 - _xyz(d)[2])
    return values


def _legendre(l: int, m: int, t: np.ndarray) -> np.ndarray:
    """Associated Legendre P_l^m(t), m >= 0, without the Condon-Shortley phase (l <= 2)."""
    s = np.sqrt(np.clip(1 - t * t, 0.0, None))
    table = {(0, 0): lambda: np.ones_like(t), (1, 0): lambda: t, (1, 1): lambda: s,
             (2, 0): lambda: 0.5 * (3 * t * t - 1), (2, 1): lambda: 3 * t * s, (2, 2): lambda: 3 * (1 - t * t)}
    return table[(l, m)]()


def hsh(d: np.ndarray) -> np.ndarray:
    """Hemispherical harmonics (Gautron 2004; spec 1.8.3) of bands 0-2, order l(l+1)+m: SH shifted by
    cos(theta) -> 2 cos(theta) - 1."""
    x, y, z = _xyz(d)
    phi = np.arctan2(y, x)
    t = 2 * np.clip(z, 0.0, 1.0) - 1
    out = []
    for l in range(3):
        for m in range(-l, l + 1):
            k = sqrt((2 * l + 1) * factorial(l - abs(m)) / (2 * pi * factorial(l + abs(m))))
            p = _legendre(l, abs(m), t)
            azimuth = 1.0 if m == 0 else sqrt(2) * (np.cos(m * phi) if m > 0 else np.sin(-m * phi))
            out.append(k * azimuth * p)
    return np.stack(out, axis=-1)


def makhotkin(d: np.ndarray) -> np.ndarray:
    """Makhotkin basis (spec 1.8.4, eq. 1.33-1.45) in its order: M00, M1-1 (x), M10, M11 (y), M2-2
    (x^2 - y^2), M2-1 (x), M20, M21 (y), M22 (xy)."""
    x, y, z = _xyz(d)
    z = np.clip(z, 0.0, 1.0)
    r = np.sqrt(z)
    w = 1 / np.sqrt(1 + z)
    return np.stack([r / sqrt(pi),
                     2 * sqrt(3 / pi) * x * z * w,
                     r * (6 * z - 4) / sqrt(2 * pi),
                     2 * sqrt(3 / pi) * y * z * w,
                     2 * sqrt(15 / pi) * z * r * (x * x - y * y) / (1 + z),
                     sqrt(3 / pi) * x * z * (10 * z - 6) * w,
                     sqrt(3 / pi) * r * (1 + 8 * (z - 1) + 10 * (z - 1) ** 2),
                     sqrt(3 / pi) * y * z * (10 * z - 6) * w,
                     4 * sqrt(15 / pi) * x * y * z * r / (1 + z)], axis=-1)


def zernike(d: np.ndarray) -> np.ndarray:
    """Zernike basis on the hemisphere (Koenderink 1996; spec 1.8.5, eq. 1.46-1.51): Z00, Z1-1, Z11,
    Z2-2, Z20, Z22."""
    x, y, z = _xyz(d)
    w = 1 / (1 + z)
    return np.stack([np.full_like(x, 1 / sqrt(2 * pi)), -sqrt(2 / pi) * y * np.sqrt(w), sqrt(2 / pi) * x * np.sqrt(w),
                     -2 * sqrt(3 / pi) * x * y * w, sqrt(3 / (2 * pi)) * (1 - 2 * z),
                     sqrt(3 / pi) * (x * x - y * y) * w], axis=-1)


@dataclass(frozen=True)
class Basis:
    """A family of basis functions: its coefficient counts (a count takes the first functions), whether it
    is orthonormal over the upper hemisphere, and its functions."""

    name: str
    label: str
    counts: tuple[int, ...]
    functions: Callable[[np.ndarray], np.ndarray]
    orthonormal: bool = True
    polynomial: bool = True  # polynomial in x, y, z (else square roots and divisions)

    def evaluate(self, directions: np.ndarray, count: int) -> np.ndarray:
        """(..., count): the first `count` functions at unit directions (..., 3)."""
        self.check(count)
        return self.functions(directions)[..., :count]

    def check(self, count: int) -> None:
        if count not in self.counts:
            raise ArsimError(f"basis '{self.name}' ({self.label}) has {' or '.join(str(c) for c in self.counts)} "
                             f"coefficients, not {count}; give one of those")


BASES = {b.name: b for b in (
    Basis("sh", "spherical harmonics", (4, 9), sh9, orthonormal=False),  # orthonormal over the sphere only
    Basis("hl2", "Half-Life 2", (3,), hl2),
    Basis("h", "H-basis", (4, 6), h_basis),
    Basis("modh", "modified H-basis", (6,), modified_h_basis, orthonormal=False),
    Basis("hsh", "hemispherical harmonics", (4, 9), hsh, polynomial=False),
    Basis("makhotkin", "Makhotkin", (4, 9), makhotkin, polynomial=False),
    Basis("zernike", "Zernike", (3, 6), zernike, polynomial=False),
)}


def get_basis(name: str) -> Basis:
    """The basis of that name; an unknown name raises ArsimError listing the known ones."""
    if name not in BASES:
        raise ArsimError(f"unknown basis '{name}'; use one of {', '.join(BASES)}")
    return BASES[name]


def parse_basis(spec: str) -> tuple[Basis, int]:
    """'h6', 'modh6', 'sh9', 'hl2' (one count: it may be left out) as (basis, count); bad names and counts
    raise ArsimError."""
    name = spec.rstrip("0123456789")
    digits = spec[len(name):]
    if name == "hl" and digits.startswith("2"):  # hl2 is a name with its digit
        name, digits = "hl2", digits[1:]
    basis = get_basis(name)
    if not digits:
        if len(basis.counts) > 1:
            raise ArsimError(f"'{spec}': say how many coefficients ({' or '.join(f'{name}{c}' for c in basis.counts)})")
        return basis, basis.counts[0]
    count = int(digits)
    basis.check(count)
    return basis, count
