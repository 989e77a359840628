"""The camera's inverse response, recovered from the recording's bracketed burst with OpenCV's
Robertson calibration, and how far it is from the true curve."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from arsim.core.errors import ArsimError

# Codes whose recovered value sets the scale: near the top where the curve is known to end (code 255 is
# full scale for every 8-bit display-referred response), as close to it as the medians reach (200-250 left
# every probe of the matrix's normal cases about 1 % too bright: a longer extrapolation over the shoulder).
# Where the burst never reaches them (a dim night at the camera's longest exposure and highest ISO), the
# highest SCALE_FIT_SPAN codes it does reach.
SCALE_FIT_CODES = np.arange(225, 255)
SCALE_FIT_SPAN = len(SCALE_FIT_CODES)
ERROR_CODES = np.arange(5, 251)  # where the error is reported: codes 0-4 are noise, 251-255 clip


@dataclass(frozen=True)
class RecoveredResponse:
    """Relative exposure (0 to 1, 1 = full scale) of each 8-bit code, per channel: linear[code, c]."""

    linear: np.ndarray  # (256, 3) float64, non-decreasing


def _fill_and_scale(curve: np.ndarray) -> np.ndarray:
    """Robertson's curve (the channels' geometric mean): codes it never saw filled by interpolation in log, made
    non-decreasing, and scaled so that the curve extrapolated to code 255 is 1 (a quadratic in the code
    fitted to the log over SCALE_FIT_CODES: Robertson's own value at 255 mixes every clipped level)."""
    codes = np.arange(256)
    good = np.isfinite(curve) & (curve > 0)
    good[255] = False  # Robertson's value at 255 mixes every clipped level
    top = codes[good][-1] if good.any() else 0
    if good.sum() < SCALE_FIT_SPAN or top < SHAPE_CODES[1]:
        raise ArsimError("the response burst does not reach the upper codes: the burst frames are too dark to "
                         "calibrate the response; record again with more burst frames or a larger burst_step")
    log = np.interp(codes, codes[good], np.log(curve[good]))
    fit_codes = SCALE_FIT_CODES if good[SCALE_FIT_CODES].sum() >= SCALE_FIT_SPAN // 2 else np.arange(top - SCALE_FIT_SPAN + 1, top + 1)
    fit = good[fit_codes]
    coefficients = np.polyfit(fit_codes[fit], log[fit_codes][fit], 2)
    linear = np.exp(log - np.polyval(coefficients, 255.0))
    linear[0] = 0.0  # code 0 holds everything below the first step
    linear[255] = max(1.0, linear[254])  # full scale (Robertson's value mixes every clipped level)
    return np.maximum.accumulate(linear)


def calibrate_response(frames: list[np.ndarray], exposure_products: np.ndarray) -> RecoveredResponse:
    """Robertson calibration of RGB 8-bit frames (H, W, 3) of one view taken with the given exposure
    products (exposure time x ISO / base ISO, seconds)."""
    if len(frames) < 2:
        raise ArsimError(f"the response burst has {len(frames)} frame(s); Robertson calibration needs at least 2 "
                         "(record with [capture] burst_frames >= 2)")
    if len(set(np.round(np.log(exposure_products), 6))) < 2:
        raise ArsimError("the response burst frames all have the same exposure; they cannot calibrate the response")
    bgr = [np.ascontiguousarray(f[..., ::-1]) for f in frames]
    with np.errstate(all="ignore"):
        curve = cv2.createCalibrateRobertson().process(bgr, np.asarray(exposure_products, dtype=np.float32))
    # One curve for the three channels (phones apply one tone curve to each): the geometric mean of
    # Robertson's three, whose differences are noise; it sets the scale within about 1 %, each alone 3-5 %.
    with np.errstate(all="ignore"):
        mean = np.exp(np.log(curve[:, 0, :].astype(np.float64)).mean(axis=1))
    linear = _fill_and_scale(_by_median_codes(frames, np.asarray(exposure_products, dtype=np.float64), _fill_and_scale(mean)))
    return RecoveredResponse(np.repeat(linear[:, None], 3, axis=1))


SHAPE_CODES = (60, 200)  # where Robertson's curve holds its shape under noise: each pixel's exposure is read there.
# Not lower: a dark pixel's exposure, the mean of the decoded codes of its frames, comes out high where the code's
# noise is a fair part of it (the decoding is convex: the mean of a convex function of a noisy code is more than
# the function of its mean). From 20: the dim studio's response 12 % too high at code 16, 5 % at 32, its
# irradiance 1.29 % off and its s = 80 13.2 %; from 60: 3 % and 1 %, 0.24 % and 7.7 % (the ideal merge 5.6 %).
# The median error over codes on seven recordings: 0.12-2.16 % from 20, 0.15-0.55 % from 60.
MEDIAN_SAMPLES = 400  # samples per exposure bin of the median code
MEDIAN_PIXELS = 200_000  # pixel-channels of the burst used (evenly spaced)


def _by_median_codes(frames: list[np.ndarray], products: np.ndarray, linear: np.ndarray) -> np.ndarray:
    """The curve read the other way round. Robertson's value for a code is the mean exposure of the pixels
    that show it; under noise, where few pixels are brighter (the top codes of a dim burst), more of those
    are dimmer pixels pushed up than brighter ones pushed down, so the top codes come out too low, and the
    scale, set there, too high (a dim night: every code 30 % too bright). Here each pixel's exposure is read
    from its mid codes (SHAPE_CODES, where the curve's shape holds), and each code's value is the exposure
    at which that code is the median code shown: the median passes through the monotone curve, the noise
    and the clipping at 0 and 255 unchanged. Codes without enough samples keep Robertson's values."""
    stack = np.stack([f.reshape(-1) for f in frames])  # (J, P) codes, channels flattened
    step = max(1, stack.shape[1] // MEDIAN_PIXELS)
    codes = stack[:, ::step].astype(np.int64)
    lo, hi = SHAPE_CODES
    use = (codes >= lo) & (codes <= hi)
    with np.errstate(all="ignore"):
        exposure = np.sum(np.where(use, linear[codes] / products[:, None], 0.0), axis=0) / use.sum(axis=0)
        # again with the frames chosen by the code each is expected to show (from that first estimate, which
        # averages many frames), not the code it shows: chosen by its own noise, a frame near the range's ends
        # is more often one pushed inside, and dark pixels' exposures came out high (once: interior 0.26 ->
        # 0.10 %, city 0.57 -> 0.30 %, the dim courtyard 1.02 -> 0.73 %; again: the largest errors grew)
        expected = np.interp(np.nan_to_num(exposure)[None, :] * products[:, None], linear, np.arange(256.0))
        use = (expected >= lo) & (expected <= hi) & (codes > 0) & (codes < 255)
        exposure = np.sum(np.where(use, linear[codes] / products[:, None], 0.0), axis=0) / use.sum(axis=0)
    seen = use.any(axis=0) & np.isfinite(exposure)
    x = (exposure[seen][None, :] * products[:, None]).ravel()  # each sample's exposure (relative)
    z = codes[:, seen].ravel()
    if len(x) < 4 * MEDIAN_SAMPLES:
        return linear
    order = np.argsort(x)
    x, z = x[order], z[order]
    n_bins = len(x) // MEDIAN_SAMPLES
    # the bins as np.array_split makes them (the first len % n_bins one sample longer), all at once
    sizes = np.full(n_bins, len(x) // n_bins)
    sizes[:len(x) % n_bins] += 1
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    middle = starts + sizes // 2
    xb = np.where(sizes % 2 == 1, x[middle], (x[middle - 1] + x[middle]) / 2)  # (x sorted: each bin's median)
    # the median code with the codes spread evenly over their unit widths (a continuous median)
    counts = np.bincount(np.repeat(np.arange(n_bins), sizes) * 256 + z, minlength=n_bins * 256)
    counts = counts.reshape(n_bins, 256).astype(np.float64)
    total = counts.sum(axis=1, keepdims=True)
    cdf = np.cumsum(counts, axis=1) / total
    c = np.argmax(cdf >= 0.5, axis=1)
    below = np.where(c > 0, cdf[np.arange(n_bins), c - 1], 0.0)
    zb = c - 0.5 + (0.5 - below) / np.maximum(counts[np.arange(n_bins), c] / total[:, 0], 1e-12)
    zb = np.maximum.accumulate(zb)
    out = linear.copy()
    target = np.arange(1, 255)
    inside = (target > zb[0]) & (target < zb[-1])
    out[target[inside]] = np.exp(np.interp(target[inside], zb, np.log(xb)))
    # above the highest median reached Robertson's values are those the noise pulls down: unknown, so that the
    # scale is fitted where the medians hold
    out[target[target >= zb[-1]]] = np.nan
    return out


def photometric_response(inverse_response: np.ndarray) -> RecoveredResponse:
    """A photometric calibration's inverse response (DSO's and TUM-VI's pcalib.txt: each code's irradiance, 255 at
    full scale) as the capture takes it: relative exposure, 1 at full scale, the same for the three channels."""
    linear = np.asarray(inverse_response, dtype=np.float64) / 255.0
    return RecoveredResponse(np.repeat(linear[:, None], 3, axis=1))


def response_error(recovered: RecoveredResponse, true_linear: np.ndarray) -> dict:
    """Relative error of the recovered inverse response against the true one (256,) over ERROR_CODES,
    in percent: median and max over codes and channels."""
    truth = np.asarray(true_linear, dtype=np.float64)[ERROR_CODES, None]
    rel = np.abs(recovered.linear[ERROR_CODES] - truth) / truth
    return {"median_pct": float(100 * np.median(rel)), "max_pct": float(100 * rel.max())}
