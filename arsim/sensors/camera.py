"""The phone camera after the lens: sensor noise, vignetting, the response curve, 8-bit frames, and the
auto-exposure loop that picks exposure time and ISO frame by frame, a few frames late.

Units: scene radiance is linear (the environment's units). At base ISO, a pixel saturates when
radiance * exposure_s * `sensitivity` reaches 1; ISO multiplies the signal (analog gain) after the
shot noise, so high ISO costs signal-to-noise as on a real sensor.
"""

from __future__ import annotations

import functools
from collections import deque
from dataclasses import dataclass, field

import numba
import numpy as np

from arsim.core.errors import ArsimError
from arsim.scenario.sections import CameraSection

RESPONSES = ("srgb", "gamma", "s-curve")
LUMA = np.array([0.2126, 0.7152, 0.0722])


def _packed_codes(codes: np.ndarray) -> np.ndarray:
    """8-bit codes four to a uint32, the first in the low byte (what the camera shader unpacks)."""
    return (codes.astype(np.uint32).reshape(-1, 4) << np.array([0, 8, 16, 24], dtype=np.uint32)).sum(axis=1, dtype=np.uint32)


@dataclass(frozen=True)
class ResponseCurve:
    """Maps relative linear exposure in [0, 1] to display values in [0, 1] and back.

    srgb: the sRGB transfer function; gamma: x^(1/gamma); s-curve: sRGB followed by a contrast S
    (0.5 + 0.5 tanh(c (y - 0.5)) / tanh(c / 2)) as phone pipelines add."""

    kind: str = CameraSection.response
    gamma: float = CameraSection.gamma
    contrast: float = CameraSection.contrast

    def __post_init__(self):
        if self.kind not in RESPONSES:
            raise ArsimError(f"response curve '{self.kind}' is unknown; use one of {', '.join(RESPONSES)}")

    def apply(self, x: np.ndarray) -> np.ndarray:
        x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
        if self.kind == "gamma":
            return x ** (1.0 / self.gamma)
        y = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
        if self.kind == "s-curve":
            c = self.contrast
            y = 0.5 + 0.5 * np.tanh(c * (y - 0.5)) / np.tanh(c / 2)
        return y

    @functools.cached_property
    def _code_thresholds(self) -> np.ndarray:
        """Relative exposures where the 8-bit code steps up: code c covers [t[c-1], t[c])."""
        return self.inverse((np.arange(255) + 0.5) / 255.0)

    @functools.cached_property
    def _code_values(self) -> np.ndarray:
        return self.inverse(np.arange(256) / 255.0)

    @functools.cached_property
    def _code_table(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Per bin of 2^20 over [0, 1]: the code at the bin's lower edge. Exact when no bin holds two
        code steps (then one comparison finishes the job); None where the curve is too steep for that."""
        bins = 1 << 20
        edges = np.arange(bins + 1) / bins
        codes = np.searchsorted(self._code_thresholds, edges, side="right")
        if np.max(np.diff(codes)) > 1:
            return None
        return codes[:-1].astype(np.int32), np.append(self._code_thresholds, np.inf)

    def encode(self, x: np.ndarray) -> np.ndarray:
        """8-bit codes round(255 apply(x)), by table lookup instead of evaluating the curve per pixel."""
        table = self._code_table
        if table is None:
            return np.searchsorted(self._code_thresholds, x, side="right").astype(np.uint8)
        low, thresholds = table
        x = np.clip(x, 0.0, 1.0)
        codes = low[np.minimum((x * len(low)).astype(np.int32), len(low) - 1)]
        codes += x >= thresholds[codes]
        return codes.astype(np.uint8)

    def thresholds_float32(self) -> np.ndarray:
        """The 255 code thresholds rounded up to float32: for a float32 x, x >= t exactly when
        x >= this (what a shader compares against)."""
        t = self._code_thresholds
        t32 = t.astype(np.float32)
        return np.where(t32.astype(np.float64) < t, np.nextafter(t32, np.float32(np.inf)), t32)

    def _bin_codes(self, bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per bin k of sqrt(x) in [k, k + 1) / bins: the code at its centre, and the codes at its ends widened by
        1e-5 of x each way (a float32 sqrt a few ulp off bins a value next door): the codes a shader can meet there."""
        k = np.arange(bins)
        thresholds = self._code_thresholds
        centre = np.searchsorted(thresholds, ((k + 0.5) / bins) ** 2, side="right")
        lowest = np.searchsorted(thresholds, (k / bins) ** 2 * (1 - 1e-5), side="right")
        highest = np.searchsorted(thresholds, ((k + 1) / bins) ** 2 * (1 + 1e-5), side="right")
        return centre, lowest, highest

    def guess_table(self, bins: int) -> tuple[np.ndarray, int]:
        """First guesses of the code for the GL camera, four 8-bit codes per uint32, and how many code
        steps a guess can be off. Bin k covers sqrt(x) in [k, k + 1) / bins (even in sqrt(x), so that
        dark values, where the curves are steep, get fine bins) and holds the code of its centre. A
        lookup instead of the curve's pow and tanh; the shader settles the guess against the exact
        thresholds. The step count allows for a float32 sqrt a few ulp off (a value binned next door)."""
        guesses, lowest, highest = self._bin_codes(bins)
        steps = int(max(np.max(guesses - lowest), np.max(highest - guesses), 1))
        return _packed_codes(guesses), steps

    def step_table(self, bins: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The GL camera's codes in one comparison, where the curve allows it: per bin of guess_table's, the lowest
        code a value binned there can have (four per uint32) and the one float32 threshold that can fall among
        those values (+inf where none), so that the code is lowest + (x >= step). None where a bin holds two
        thresholds (steep curves: gamma far from 2.2); the shader then settles guess_table's guesses."""
        _, lowest, highest = self._bin_codes(bins)
        if np.max(highest - lowest) > 1:
            return None
        steps = np.append(self.thresholds_float32(), np.float32(np.inf))[np.where(highest > lowest, lowest, 255)]
        return _packed_codes(lowest), steps.astype(np.float32)

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """Relative exposure of 8-bit codes (a 256-entry table of the inverse curve)."""
        return self._code_values[codes]

    def inverse(self, y: np.ndarray) -> np.ndarray:
        y = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0)
        if self.kind == "gamma":
            return y**self.gamma
        if self.kind == "s-curve":
            c = self.contrast
            y = 0.5 + np.arctanh(np.clip((2 * y - 1) * np.tanh(c / 2), -1 + 1e-15, 1 - 1e-15)) / c
        return np.where(y <= 0.04045, y / 12.92, ((y + 0.055) / 1.055) ** 2.4)


_DEFAULT = CameraSection()  # the defaults live in the scenario schema


@dataclass(frozen=True)
class SensorSettings:
    """Noise and limits of the image sensor and its auto-exposure ([device.camera])."""

    sensitivity: float = _DEFAULT.sensitivity  # 1 / (radiance * s) that saturates a pixel at base ISO
    full_well_e: float = _DEFAULT.full_well_e  # electrons at saturation, base ISO
    read_noise_e: float = _DEFAULT.read_noise_e
    base_iso: float = _DEFAULT.base_iso
    iso_range: tuple[float, float] = (_DEFAULT.iso_min, _DEFAULT.iso_max)
    exposure_range_s: tuple[float, float] = (_DEFAULT.exposure_min_s, _DEFAULT.exposure_max_s)
    vignetting: float = _DEFAULT.vignetting  # relative fall-off at the image corners
    target_grey: float = _DEFAULT.target_grey  # metered linear level the auto-exposure aims for
    convergence: float = _DEFAULT.convergence  # fraction of the log error corrected per frame
    latency_frames: int = _DEFAULT.latency_frames  # frames before a new exposure takes effect
    clipped_step: float = 4.0  # extra factor when most of a frame is clipped (its level is unknown)
    settle_frames: int = _DEFAULT.settle_frames  # promise: within 10 % of the target this many frames after a step

    @classmethod
    def of(cls, section: CameraSection) -> SensorSettings:
        return cls(section.sensitivity, section.full_well_e, section.read_noise_e, section.base_iso,
                   (section.iso_min, section.iso_max), (section.exposure_min_s, section.exposure_max_s),
                   section.vignetting, section.target_grey, section.convergence, section.latency_frames,
                   settle_frames=section.settle_frames)

    def check(self) -> None:
        if not (0 < self.iso_range[0] <= self.iso_range[1]):
            raise ArsimError(f"ISO range {self.iso_range} is not allowed: give 0 < min <= max")
        if not (0 < self.exposure_range_s[0] <= self.exposure_range_s[1]):
            raise ArsimError(f"exposure range {self.exposure_range_s} s is not allowed: give 0 < min <= max")
        if not 0 < self.convergence <= 1:
            raise ArsimError(f"auto-exposure convergence {self.convergence} is not allowed: give (0, 1]")
        if self.latency_frames < 0 or self.read_noise_e < 0 or self.full_well_e <= 0:
            raise ArsimError("latency, read noise must be 0 or more and the full well positive")


def vignette(height: int, width: int, strength: float) -> np.ndarray:
    """Relative illumination (H, W): 1 at the centre, 1 - strength at the corners, smooth (r^4 law)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    r2 = ((x - (width - 1) / 2) ** 2 + (y - (height - 1) / 2) ** 2) / (((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2)
    return 1.0 - strength * r2 * r2


def pcg_hash(v: np.ndarray) -> np.ndarray:
    """The PCG hash (Jarzynski and Olano 2020) on uint32, as shaders/camera_frame.comp computes it."""
    v = np.asarray(v, dtype=np.uint32)
    with np.errstate(over="ignore"):  # arithmetic modulo 2^32 is the point
        state = v * np.uint32(747796405) + np.uint32(2891336453)
        word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


NOISE_STREAMS = {"capture": 1, "burst": 2, "ar": 3}


def noise_key(seed: int, stream: str, frame: int) -> int:
    """The 32-bit key of one frame's noise: a hash chain of seed, stream and frame index."""
    key = pcg_hash(np.uint32(seed & 0xFFFFFFFF))
    key = pcg_hash(key + np.uint32(NOISE_STREAMS[stream]))
    return int(pcg_hash(key + np.uint32(frame & 0xFFFFFFFF)))


def pixel_normals(key: int, height: int, width: int) -> np.ndarray:
    """Standard normals (H, W, 3) float32 of one frame, so that every pixel's noise is known without a
    sequential generator and the GL camera (camera_frame.comp) draws the very same numbers: per pixel p
    (row-major) four hashed uniforms u_j of 4 p + j, and Box-Muller on the pairs (u_0, u_1) (its cosine
    and sine: red, green) and (u_2, u_3) (its cosine: blue)."""
    p = np.arange(height * width, dtype=np.uint32)[:, None]
    hashed = pcg_hash(np.uint32(4) * p + np.arange(4, dtype=np.uint32) + np.uint32(key))
    u = ((hashed >> np.uint32(8)) + np.uint32(1)).astype(np.float32) * np.float32(1.0 / 16777216.0)
    two_pi = np.float32(2.0) * np.float32(np.pi)
    radius = np.sqrt(np.float32(-2.0) * np.log(u[:, 0::2]))
    angle = two_pi * u[:, 1::2]
    normals = np.stack([radius[:, 0] * np.cos(angle[:, 0]), radius[:, 0] * np.sin(angle[:, 0]),
                        radius[:, 1] * np.cos(angle[:, 1])], axis=-1)
    return normals.reshape(height, width, 3)


def expose(radiance: np.ndarray, exposure_s: float, iso: float, sensor: SensorSettings, response: ResponseCurve,
           normals: np.ndarray, falloff: np.ndarray | None = None) -> np.ndarray:
    """An 8-bit RGB frame (H, W, 3) of the scene radiance: photons to electrons with shot and read
    noise (normals: standard normals of the frame's shape, see pixel_normals), analog gain, clipping,
    the response curve, and quantisation. The NumPy reference of the GL camera (views.CameraRenderer)."""
    falloff = vignette(*radiance.shape[:2], sensor.vignetting) if falloff is None else falloff
    # float32 throughout: the result is 8 bits, and a 640 x 480 frame is 0.9 M samples per channel.
    scale = np.float32(exposure_s * sensor.sensitivity * sensor.full_well_e)
    electrons = np.maximum(radiance.astype(np.float32) * scale * falloff[..., None].astype(np.float32), 0.0)
    electrons += normals.astype(np.float32) * np.sqrt(electrons + np.float32(sensor.read_noise_e**2))
    signal = electrons * np.float32(iso / sensor.base_iso / sensor.full_well_e)
    return response.encode(signal)


@functools.lru_cache(maxsize=8)
def _metering_weights(height: int, width: int) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    weight = np.exp(-(((x - width / 2) / (0.35 * width)) ** 2 + ((y - height / 2) / (0.35 * height)) ** 2))
    return weight / weight.sum()


METERING_STEP = 4  # camera pipelines meter on low-resolution statistics: every fourth pixel each way


@numba.njit(cache=True, nogil=True)
def _meter(frame: np.ndarray, linear_of_code: np.ndarray, luma: np.ndarray, weights: np.ndarray) -> tuple:
    """Over the metering grid of an 8-bit frame: the weighted mean linear luminance, and the fractions
    of samples (pixels and channels) at 255 and at 0. One pass, straight from the frame's memory."""
    level, white, black = 0.0, 0, 0
    for i in range(weights.shape[0]):
        for j in range(weights.shape[1]):
            y = 0.0
            for c in range(3):
                code = frame[METERING_STEP * i, METERING_STEP * j, c]
                y += linear_of_code[code] * luma[c]
                white += code >= 255
                black += code <= 0
            level += y * weights[i, j]
    samples = 3 * weights.size
    return level, white / samples, black / samples


def metering(frame: np.ndarray, response: ResponseCurve) -> tuple[float, float, float]:
    """(level, white, black) of a frame: its centre-weighted mean linear luminance (what the
    auto-exposure measures) and the fractions of clipped samples, on every METERING_STEP-th pixel."""
    height, width = -(-frame.shape[0] // METERING_STEP), -(-frame.shape[1] // METERING_STEP)
    return _meter(frame, response.decode(np.arange(256)), LUMA, _metering_weights(height, width))


def metered_level(frame: np.ndarray, response: ResponseCurve) -> float:
    """Centre-weighted mean linear luminance of an 8-bit frame (what the auto-exposure measures)."""
    return float(metering(frame, response)[0])


@dataclass
class AutoExposure:
    """Frame-by-frame exposure control: meter the last frame, move the exposure product a fraction of
    the way (in log) towards the target, and apply the result `latency_frames` later. The product is
    split into exposure time first (up to its limit), then ISO."""

    sensor: SensorSettings
    response: ResponseCurve
    product: float = 1.0 / 30.0  # exposure_s * iso / base_iso
    pending: deque = field(default_factory=deque)

    def __post_init__(self):
        self.sensor.check()
        self.pending = deque([self.product] * self.sensor.latency_frames)

    def settings(self, product: float) -> tuple[float, float]:
        """(exposure_s, iso) for an exposure product, within the limits."""
        s = self.sensor
        exposure = float(np.clip(product, *s.exposure_range_s))
        iso = float(np.clip(product / exposure * s.base_iso, *s.iso_range))
        return exposure, iso

    def next_frame_settings(self) -> tuple[float, float]:
        """The (exposure_s, iso) the next frame is taken with (decided `latency_frames` ago)."""
        self.pending.append(self.product)
        return self.settings(self.pending.popleft())

    def update(self, frame: np.ndarray, used: tuple[float, float]) -> None:
        """Meter a frame taken with `used` settings and steer the product for frames to come."""
        level, white, black = metering(frame, self.response)
        level = max(level, 1e-4)
        used_product = used[0] * used[1] / self.sensor.base_iso
        wanted = used_product * self.sensor.target_grey / level
        s = self.sensor
        lo = s.exposure_range_s[0] * s.iso_range[0] / s.base_iso
        hi = s.exposure_range_s[1] * s.iso_range[1] / s.base_iso
        # A mostly white (black) frame only bounds the right product from above (below): jump below
        # (above) that bound by clipped_step. Frames taken before earlier jumps (latency) repeat an old
        # bound and change nothing, so the jumps do not compound.
        if white > 0.5:
            self.product = float(np.clip(min(self.product, wanted / s.clipped_step), lo, hi))
        elif black > 0.5:
            self.product = float(np.clip(max(self.product, wanted * s.clipped_step), lo, hi))
        else:
            step = np.exp(s.convergence * np.log(wanted / self.product))
            self.product = float(np.clip(self.product * step, lo, hi))
