"""Accumulation of camera frames into an HDR angle map (Kán's method): every texel whose direction
falls inside a frame gets the frame's radiance there, weighted, and the probe is sum(w L) / sum(w).

Weights per pixel and channel: a weight on the 8-bit code (1 up to mid-grey, falling to 0 at 255: a
dark code counts as much as a mid one, so that noise does not bias dark texels upward) times a centre
weight (the frame's vignetted edges and its rim count less) times the frame's trust, the square of its exposure (one code step is a radiance step inversely proportional to the
exposure: the weight is the inverse of that quantisation variance). A frame bracketed 14 EV down for
the highlights thus adds nothing measurable where a metered frame saw the scene well, and is all
there is where every metered frame clipped. Samples are bilinear with the weights inside (sum of
b w L / sum of b w over the four pixels); where any of the four pixels is clipped the frame adds
nothing there (the texel may be as bright as the clipped pixel, and its unclipped neighbours would
understate it: a lamp's core would take the value of its rim) but a clipped vote.

Frames are kept apart by exposure level (the bracket offsets), each level with its own sums and its
votes (clipped or not, weighted by the bilinear and centre weights). A texel's radiance comes from
the longest level whose frames mostly saw it unclipped, and the shorter ones: at a lamp's rim the
few metered frames that a residual orientation error put just beside it would otherwise outweigh
every short exposure that saw the lamp there (by the exposure squared, 2^28 at 14 EV), and the lamp
would shrink to where every frame clipped (default sweep: 12 % of the brightest lamp's energy lost at
0.2-0.3 degrees of error). A texel only ever seen clipped keeps the largest lower bound of its
radiance (the full-scale value of the shortest exposure that saw it) and is flagged as clipped.

The noise of the darkest texels is clipped at code 0 (the sensor reads no negative signal), which biases
their mean upward: the studio's walls, seen at the camera's longest exposure and highest ISO just above
its read noise, came out 47 % too bright at the true orientations (irradiance 0.22 %, s = 80 26.5 %). Per
texel and level, the accumulator keeps beside the weighted mean the weighted mean of its samples' variance
under the camera's noise model (shot and read noise: Var(L) = (g x / FW + (g r / FW)²) / (s v)² at a
sample's relative exposure x, gain g, full well FW, read noise r, exposure s, fall-off v), and `probe()`
removes the bias of a Gaussian clipped at 0 from the longest level's mean where that level mostly saw
the texel unclipped (the walls -3 %; irradiance 0.14 %, s = 80 2.6 %).

Noise-optimal weights (Granados et al. 2010, Hasinoff et al. 2010: each sample weighted by the inverse of
that variance, taken at the radiance a first pass found) were built and measured at the true orientations
against these code weights, both with the correction: the default sweep 0.12 -> 0.09 % irradiance and
0.16 -> 0.13 % s = 80, the studio 0.14 -> 0.14 % and 2.6 -> 4.7 %. The code weights stay.

`ProbeAccumulator.add` runs compiled (numba, both cores); `accumulate_reference` is the NumPy oracle
of one frame's contribution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
from scipy import special

from arsim.core.conventions import CameraIntrinsics, anglemap_directions, anglemap_disk_mask, anglemap_solid_angles


def hat_weights(level: int = 0) -> np.ndarray:
    """Weight of each 8-bit code (256,) in a frame of this exposure level: for the longest, 1 up to
    mid-grey, falling to 0 at 255; for the shorter ones, 1 but at 255. Not a hat rising from code 0: a
    weight that grows with the observed code biases a noisy dark texel upward (its mean weighted by
    itself is E[c²]/E[c], the noise's variance over the mean too bright, and code 0 clipped away), which
    left the night's and the dim scenes' dark walls 6-17 % too bright (night s = 80 error 10.6 % -> 3.6 %,
    the default's 1.61 -> 1.13 %). Those frames are there
    for the highlights, and what a sample of theirs says is dominated by where it lands (a lamp a few
    pixels wide, registered to a fraction of a degree), not by its noise: a dark sample beside a lamp
    says "not the lamp here" as loudly as a bright one says "the lamp", or the lamp would grow by
    every frame's registration error."""
    codes = np.arange(256, dtype=np.float64)
    if level > 0:
        return np.where(codes < 255, 1.0, 0.0)
    return np.minimum(127.5, 255.0 - codes) / 127.5


@dataclass(frozen=True)
class SensorNoise:
    """The sensor's noise figures in electrons: the full well (at base ISO) and the read noise."""

    full_well_e: float
    read_noise_e: float


# m / sigma of clipped Gaussian samples (h) against mu / sigma (z): what clip_corrected inverts
_CLIP_Z = np.linspace(-6.0, 8.0, 4001)
_CLIP_H = _CLIP_Z * special.ndtr(_CLIP_Z) + np.exp(-0.5 * _CLIP_Z * _CLIP_Z) / np.sqrt(2 * np.pi)


def clip_corrected(mean: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The mean mu of Gaussian samples (standard deviation sigma) that were clipped at 0, from the clipped
    samples' mean m: m = mu Phi(mu / sigma) + sigma phi(mu / sigma) solved for mu (at least 0). Where m is
    over 8 sigma the clipping changed nothing measurable."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = mean / sigma
    return np.where(ratio > 8.0, mean, np.maximum(np.interp(ratio, _CLIP_H, _CLIP_Z), 0.0) * sigma)


@numba.njit(cache=True, parallel=True)
def _clip_corrected_probe(radiance, sums, weights, variances, unclipped_votes, clipped_votes, h, z):
    """ProbeAccumulator.probe with the noise's correction, per texel (the longest level's maps (N, N, 3)):
    what its NumPy form computes over the whole map at every call (a snapshot a second took 65 ms)."""
    out = np.empty(radiance.shape, np.float32)
    for r in numba.prange(radiance.shape[0]):
        for c in range(radiance.shape[1]):
            for ch in range(3):
                value = max(radiance[r, c, ch], 0.0)
                w = weights[r, c, ch]
                if value > 0.0 and w > 0.0 and unclipped_votes[r, c, ch] >= clipped_votes[r, c, ch]:
                    mean, sigma = sums[r, c, ch] / w, np.sqrt(variances[r, c, ch] / w)
                    if sigma > 0.0:
                        ratio = mean / sigma
                        corrected = mean if ratio > 8.0 else max(np.interp(ratio, h, z), 0.0) * sigma
                        value = max(value - (mean - corrected), 0.0)
                out[r, c, ch] = value
    return out


def centre_weights(camera: CameraIntrinsics, falloff: np.ndarray) -> np.ndarray:
    """Weight of each pixel (H, W): its vignetting fall-off times a window that reaches 0 at the
    frame's rim (so frames blend without seams)."""
    y, x = np.mgrid[0:camera.height, 0:camera.width]
    u = (x - camera.cx) / (camera.width / 2.0)
    v = (y - camera.cy) / (camera.height / 2.0)
    window = np.clip(1.0 - u * u, 0.0, 1.0) * np.clip(1.0 - v * v, 0.0, 1.0)
    return (falloff * window).astype(np.float32)


@numba.njit(cache=True, nogil=True, inline="always")
def _project(d0, d1, d2, fx, fy, cx, cy, k1, k2):
    x, y = d0 / d2, d1 / d2
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2
    return fx * x * radial + cx, fy * y * radial + cy


@numba.njit(cache=True, nogil=True, inline="always")
def merged_radiance(sums, weights, clipped_votes, unclipped_votes, bound, r, c, ch):
    """One texel's radiance from the per-level maps (levels, N, N, 3), longest exposure first: the
    weighted mean over the longest level whose votes there are mostly unclipped and all shorter ones
    (any level's samples where every level mostly clipped, but no less than the lower bound); the
    lower bound where nothing was measured; -1 where nothing was seen at all."""
    levels = sums.shape[0]
    first = levels
    for level in range(levels):
        unclipped = unclipped_votes[level, r, c, ch]
        if unclipped > 0.0 and unclipped >= clipped_votes[level, r, c, ch]:
            first = level
            break
    num, den = 0.0, 0.0
    for level in range(first, levels):
        num += sums[level, r, c, ch]
        den += weights[level, r, c, ch]
    if den > 0.0:
        return num / den
    for level in range(levels):
        num += sums[level, r, c, ch]
        den += weights[level, r, c, ch]
    if den > 0.0:
        return max(num / den, bound[r, c, ch])
    return bound[r, c, ch] if bound[r, c, ch] > 0.0 else -1.0


CHUNK = 64  # disk texels per chunk of the frame's culling (ProbeAccumulator orders them tile by tile)


def chunk_cones(directions: np.ndarray, chunk: int = CHUNK) -> np.ndarray:
    """Per chunk of `chunk` consecutive texel directions (K, 3): (axis x, y, z, angular radius in radians), a
    cone that holds every direction of the chunk (its radius rounded up: the culling must never drop a texel)."""
    count = -(-len(directions) // chunk)
    padded = np.concatenate([directions, np.repeat(directions[-1:], count * chunk - len(directions), axis=0)])
    groups = padded.reshape(count, chunk, 3)
    axis = groups.sum(axis=1)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    radius = np.arccos(np.clip(np.einsum("gkc,gc->gk", groups, axis).min(axis=1), -1.0, 1.0))
    return np.column_stack([axis, radius + 1e-6])


@numba.njit(cache=True, nogil=True)
def _chunks_in_view(cones, optical_axis, min_cos):
    """Indices of the chunks whose cone (chunk_cones) meets the frame's: directions within acos(min_cos) of the
    optical axis (world)."""
    reach = math.acos(max(min(min_cos, 1.0), -1.0))
    found = np.empty(cones.shape[0], np.int64)
    count = 0
    for g in range(cones.shape[0]):
        dot = cones[g, 0] * optical_axis[0] + cones[g, 1] * optical_axis[1] + cones[g, 2] * optical_axis[2]
        if math.acos(max(min(dot, 1.0), -1.0)) <= reach + cones[g, 3]:
            found[count] = g
            count += 1
    return found[:count]


@numba.njit(cache=True, parallel=True, nogil=True)
def _accumulate(directions, rows, cols, chunks, world_to_camera, intrinsics, min_cos, codes, radiance_of_code, hat,
                centre, exposure, sums, weights, clipped_votes, unclipped_votes, variances, level, bound, radiance,
                gain, full_well, read_noise):
    """For every disk texel (directions (K, 3), at rows, cols of the maps) inside the frame: add the
    weighted bilinear sample of the frame to its level's sums and weights and its vote to
    unclipped_votes, or, where any of the four pixels is clipped, its vote to clipped_votes and raise
    bound; then merge the texel's radiance anew. radiance_of_code (256, 3): this frame's radiance per
    code before vignetting; centre (H, W, 2): the pixel weights and the fall-off divided out of the
    radiance. Only the texels of `chunks` (_chunks_in_view) are visited: a frame sees a few per cent of the
    sphere, and its texels, one blob of the map, split by rows between the threads left one of them idle."""
    fx, fy, cx, cy, k1, k2 = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3], intrinsics[4], intrinsics[5]
    height, width = codes.shape[0], codes.shape[1]
    m = world_to_camera
    trust = exposure * exposure
    for i in numba.prange(chunks.size * CHUNK):
        k = chunks[i // CHUNK] * CHUNK + i % CHUNK
        if k >= directions.shape[0]:
            continue
        w0, w1, w2 = directions[k, 0], directions[k, 1], directions[k, 2]
        d2 = m[2, 0] * w0 + m[2, 1] * w1 + m[2, 2] * w2
        if d2 < min_cos:  # outside the cone around the optical axis that holds the frame
            continue
        d0 = m[0, 0] * w0 + m[0, 1] * w1 + m[0, 2] * w2
        d1 = m[1, 0] * w0 + m[1, 1] * w1 + m[1, 2] * w2
        px, py = _project(d0, d1, d2, fx, fy, cx, cy, k1, k2)
        if not (0.0 <= px <= width - 1 and 0.0 <= py <= height - 1):
            continue
        x0, y0 = min(int(px), width - 2), min(int(py), height - 2)
        ax, ay = px - x0, py - y0
        r, c = rows[k], cols[k]
        for ch in range(3):
            num, den, vote, clipped, spread = 0.0, 0.0, 0.0, 0, 0.0
            for j in range(4):
                x, y = x0 + (j & 1), y0 + (j >> 1)
                b = (ax if j & 1 else 1.0 - ax) * (ay if j >> 1 else 1.0 - ay)
                code = codes[y, x, ch]
                v = b * centre[y, x, 0]
                w = v * hat[code] * trust
                num += w * radiance_of_code[code, ch] / centre[y, x, 1]
                den += w
                vote += v
                clipped += code == 255
                if full_well > 0.0:  # Var(L) = (g x / FW + (g r / FW)²) / (s v)², x the code's relative exposure
                    relative = radiance_of_code[code, ch] * exposure
                    scale = exposure * centre[y, x, 1]
                    spread += w * (gain * relative / full_well + (gain * read_noise / full_well) ** 2) / (scale * scale)
            if clipped == 0:
                sums[level, r, c, ch] += num
                weights[level, r, c, ch] += den
                unclipped_votes[level, r, c, ch] += vote
                variances[level, r, c, ch] += spread
            else:  # a texel next to clipped pixels may be as bright: its unclipped neighbours would understate it
                clipped_votes[level, r, c, ch] += vote
                lower = radiance_of_code[255, ch] / centre[y0, x0, 1]
                if lower > bound[r, c, ch]:
                    bound[r, c, ch] = lower
            radiance[r, c, ch] = merged_radiance(sums, weights, clipped_votes, unclipped_votes, bound, r, c, ch)


class ProbeAccumulator:
    """The N x N angle map being captured: per exposure level, running sums, weights and votes; the
    clipped lower bounds."""

    def __init__(self, size: int, camera: CameraIntrinsics, falloff: np.ndarray, levels: int = 1,
                 sensor: SensorNoise | None = None):
        """sensor: its noise figures, for the correction of the noise clipped at code 0 (none without)."""
        self.size, self.camera = size, camera
        self.sensor = sensor
        inside = anglemap_disk_mask(size)
        rows, cols = np.nonzero(inside)
        # The disk texels in 8 x 8 tiles (the kernel's chunks of 64 stay compact on the sphere), each texel's
        # work its own: the order changes no value.
        order = np.lexsort((cols, rows, cols // 8, rows // 8))
        self.rows, self.cols = rows[order].astype(np.int32), cols[order].astype(np.int32)
        self.directions = np.ascontiguousarray(anglemap_directions(size)[self.rows, self.cols], dtype=np.float64)
        self.cones = chunk_cones(self.directions)
        # Per pixel: (centre weight, vignetting fall-off), as the kernel reads both at once.
        self.centre = np.ascontiguousarray(np.stack([centre_weights(camera, falloff), falloff.astype(np.float32)], axis=-1))
        self.intrinsics = np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.k1, camera.k2])
        corners = camera.unproject(np.array([[0, 0], [camera.width - 1, 0], [0, camera.height - 1],
                                             [camera.width - 1, camera.height - 1]], dtype=np.float64))
        self.min_cos = float(corners[:, 2].min()) - 1e-3  # a little wider than the frame's corners
        self.hats = [hat_weights(level) for level in range(levels)]
        self.sums, self.weights, self.clipped_votes, self.unclipped_votes, self.variances = (
            np.zeros((levels, size, size, 3)) for _ in range(5))
        self.bound = np.zeros((size, size, 3))
        self.radiance = np.full((size, size, 3), -1.0)  # merged after every frame where it saw; -1: unseen
        self.solid_angles = anglemap_solid_angles(size)

    @property
    def levels(self) -> tuple[np.ndarray, ...]:
        """Per exposure level (levels, N, N, 3): sums, weights, clipped and unclipped votes, variances."""
        return self.sums, self.weights, self.clipped_votes, self.unclipped_votes, self.variances

    def add(self, codes: np.ndarray, radiance_of_code: np.ndarray, camera_to_world: np.ndarray, exposure: float = 1.0,
            level: int = 0, gain: float = 1.0) -> None:
        """Accumulate one frame: 8-bit codes (H, W, 3), its radiance per code before vignetting (256, 3),
        the camera-to-world rotation matrix it was taken with, its exposure (radiance x exposure is the
        relative exposure its codes encode; squared, the trust of the code weights), its exposure level
        (0: the longest) and its gain (ISO over base ISO: for its samples' noise)."""
        full_well, read_noise = (self.sensor.full_well_e, self.sensor.read_noise_e) if self.sensor else (0.0, 0.0)
        world_to_camera = np.ascontiguousarray(np.asarray(camera_to_world).T)
        chunks = _chunks_in_view(self.cones, np.ascontiguousarray(world_to_camera[2]), self.min_cos)
        _accumulate(self.directions, self.rows, self.cols, chunks, world_to_camera, self.intrinsics, self.min_cos,
                    codes, np.ascontiguousarray(radiance_of_code, dtype=np.float64),
                    self.hats[level], self.centre, float(exposure), *self.levels, level, self.bound, self.radiance,
                    float(gain), float(full_well), float(read_noise))

    def probe(self) -> np.ndarray:
        """The captured angle map (N, N, 3) float32 (see merged_radiance); 0 where never seen. With the sensor's
        noise figures, texels the longest exposures mostly saw unclipped lose the bias their noise clipped at
        code 0 gave them (clip_corrected, on that level's mean and noise)."""
        if self.sensor is None:
            return np.maximum(self.radiance, 0.0).astype(np.float32)
        return _clip_corrected_probe(self.radiance, self.sums[0], self.weights[0], self.variances[0],
                                     self.unclipped_votes[0], self.clipped_votes[0], _CLIP_H, _CLIP_Z)

    def covered(self) -> np.ndarray:
        """(N, N) bool: texels with a value in every channel (measured, or a clipped lower bound)."""
        # merged_radiance's -1: neither (channel by channel: np.all over the last axis took 9x as long)
        r = self.radiance
        return (r[..., 0] >= 0.0) & (r[..., 1] >= 0.0) & (r[..., 2] >= 0.0)

    def clipped_only(self) -> np.ndarray:
        """(N, N) bool: texels where some channel is only a lower bound (always seen clipped)."""
        return np.any((self.weights.sum(axis=0) == 0) & (self.bound > 0), axis=-1)

    def coverage(self) -> float:
        """Fraction of the sphere's solid angle covered."""
        return float(self.solid_angles[self.covered()].sum() / self.solid_angles.sum())


def accumulate_reference(size: int, camera: CameraIntrinsics, falloff: np.ndarray, codes: np.ndarray,
                         radiance_of_code: np.ndarray, camera_to_world: np.ndarray,
                         exposure: float = 1.0, level: int = 0, gain: float = 1.0,
                         sensor: SensorNoise | None = None) -> tuple[np.ndarray, ...]:
    """NumPy oracle of one frame added to an empty accumulator's level: (sums, weights, clipped votes,
    unclipped votes, variances), each (N, N, 3)."""
    inside = anglemap_disk_mask(size)
    directions = anglemap_directions(size)[inside]
    local = directions @ np.asarray(camera_to_world)  # world to camera: R^T d
    maps = np.zeros((5, size, size, 3))  # sums, weights, clipped and unclipped votes, variances
    front = local[:, 2] > 1e-9
    px = np.full((len(local), 2), -1.0)
    px[front] = camera.project(local[front])
    ok = front & (px[:, 0] >= 0) & (px[:, 0] <= camera.width - 1) & (px[:, 1] >= 0) & (px[:, 1] <= camera.height - 1)
    x0 = np.minimum(px[ok, 0].astype(int), camera.width - 2)
    y0 = np.minimum(px[ok, 1].astype(int), camera.height - 2)
    ax, ay = px[ok, 0] - x0, px[ok, 1] - y0
    centre, hat = centre_weights(camera, falloff).astype(np.float64), hat_weights(level)
    num, den, vote = np.zeros((ok.sum(), 3)), np.zeros((ok.sum(), 3)), np.zeros((ok.sum(), 1))
    spread = np.zeros((ok.sum(), 3))
    clipped = np.zeros((ok.sum(), 3), bool)
    target = np.flatnonzero(inside.ravel())[ok]
    for dy in (0, 1):
        for dx in (0, 1):
            b = (ax if dx else 1 - ax) * (ay if dy else 1 - ay)
            y, x = y0 + dy, x0 + dx
            c = codes[y, x].astype(int)
            w = b[:, None] * hat[c] * centre[y, x][:, None] * exposure**2
            if sensor is not None:
                relative = radiance_of_code[c, np.arange(3)] * exposure
                scale = exposure * falloff[y, x][:, None]
                spread += w * (gain * relative / sensor.full_well_e + (gain * sensor.read_noise_e / sensor.full_well_e) ** 2) / scale**2
            num += w * radiance_of_code[c, np.arange(3)] / falloff[y, x][:, None]
            den += w
            vote += (b * centre[y, x])[:, None]
            clipped |= c == 255
    num[clipped], den[clipped], spread[clipped] = 0.0, 0.0, 0.0  # next to a clipped pixel a frame says nothing but its vote
    for k, values in enumerate([num, den, np.where(clipped, vote, 0.0), np.where(clipped, 0.0, vote), spread]):
        maps[k].reshape(-1, 3)[target] = values
    return tuple(maps)


def filled(probe: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """The probe with uncovered disk texels filled from their covered surroundings (normalised
    convolution at growing widths), so that maps can be computed from it."""
    out = probe.astype(np.float32).copy()
    have = covered.astype(np.float32)
    sigma = 2.0
    while (have < 1).any() and sigma < probe.shape[0]:
        num = cv2.GaussianBlur(out * have[..., None], (0, 0), sigma)
        den = cv2.GaussianBlur(have, (0, 0), sigma)
        fill = (have < 1) & (den > 1e-3)
        out[fill] = num[fill] / den[fill, None]
        have = np.where(fill, 1.0, have)
        sigma *= 2
    return out * anglemap_disk_mask(probe.shape[0])[..., None]
