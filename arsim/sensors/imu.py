"""IMU streams as a phone reports them: gyroscope (rad/s), accelerometer (m/s²), magnetometer (µT),
in Android device axes, each at its own rate, with the errors of a MEMS sensor.

Per sample k at time t_k (nominal k / rate plus timestamp jitter), per axis:
    reading = clip(quantise(M true(t_k) + b_on + b_rw(t_k) + b_gm(t_k) + w_k))
with M = I + scale-factor errors + axis misalignment (fixed per device), b_on the turn-on bias, b_rw a
random walk (density `bias_random_walk`), b_gm a first-order Gauss-Markov process (`bias_instability`
with correlation time `bias_correlation_s`, the usual model of the Allan-deviation floor) and w white
noise of density `noise_density` (standard deviation noise_density * sqrt(rate)).

Defaults (in the scenario schema, arsim/scenario/sections.py): the noise densities and ranges of the TDK
InvenSense ICM-42688-P (datasheet DS-000347: gyroscope 2.8 mdps/sqrt(Hz), accelerometer 70 µg/sqrt(Hz),
±2000 dps, ±16 g, 19/18-bit FIFO data) and of the AKM AK09918 magnetometer (0.15 µT per LSB, ±4900 µT);
biases, random walks, scale factors and misalignments are not in those datasheets and are typical
residuals after a phone's own calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import numba

from arsim.core.errors import ArsimError
from arsim.scenario import sections
from arsim.sensors.trajectory import Trajectory

DEG = np.pi / 180.0

# The Earth's field in world axes (+y up, north along -z): 48 µT, inclined 60 degrees downwards.
EARTH_FIELD_UT = 48.0 * np.array([0.0, -np.sin(60 * DEG), -np.cos(60 * DEG)])


@dataclass(frozen=True)
class SensorModel:
    """Error model of one three-axis sensor; units are those of its readings (rad/s, m/s², µT)."""

    rate_hz: float
    noise_density: float  # per sqrt(Hz)
    bias_random_walk: float = 0.0  # per sqrt(s)
    bias_instability: float = 0.0  # standard deviation of the Gauss-Markov bias
    bias_correlation_s: float = 100.0
    turn_on_bias: float = 0.0  # standard deviation, per axis
    scale_factor: float = 0.0  # standard deviation (fraction), per axis
    misalignment_rad: float = 0.0  # standard deviation of each cross-axis term
    full_scale: float = np.inf  # readings saturate at ±full_scale
    resolution: float = 0.0  # LSB; 0 means no quantisation
    jitter_s: float = 0.0  # standard deviation of the sampling instant

    def check(self, name: str) -> None:
        if not self.rate_hz > 0:
            raise ArsimError(f"{name}: rate {self.rate_hz} Hz is not allowed: give a positive rate")
        for key in ("noise_density", "bias_random_walk", "bias_instability", "turn_on_bias", "scale_factor",
                    "misalignment_rad", "resolution", "jitter_s"):
            if getattr(self, key) < 0:
                raise ArsimError(f"{name}: {key} = {getattr(self, key)} is negative; noise terms are 0 or more")


def sensor_model(section) -> SensorModel:
    """The error model of a [device.gyroscope|accelerometer|magnetometer] section."""
    return SensorModel(**{f.name: getattr(section, f.name) for f in fields(SensorModel)})


# The defaults live in the scenario schema (arsim/scenario/sections.py), the one place users see them.
GYROSCOPE = sensor_model(sections.GYROSCOPE)
ACCELEROMETER = sensor_model(sections.ACCELEROMETER)
MAGNETOMETER = sensor_model(sections.MAGNETOMETER)


@dataclass(frozen=True)
class SensorStream:
    """Readings of one sensor: timestamps in ns (int64, increasing) and values (K, 3)."""

    name: str
    t_ns: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class SensorErrors:
    """The fixed errors drawn for one device (kept, so the evaluation knows them)."""

    matrix: np.ndarray  # M = I + scale + misalignment
    turn_on_bias: np.ndarray  # (3,)


def _gauss_markov(n: int, dt: float, sigma: float, tau: float, rng: np.random.Generator) -> np.ndarray:
    """First-order Gauss-Markov samples (n, 3), stationary with standard deviation sigma."""
    if sigma == 0 or n == 0:
        return np.zeros((n, 3))
    phi = np.exp(-dt / tau)
    drive = rng.standard_normal((n, 3)) * sigma * np.sqrt(1.0 - phi * phi)
    state = rng.standard_normal(3) * sigma
    return _first_order_recursion(drive, phi, state)


@numba.njit(cache=True)
def _first_order_recursion(drive: np.ndarray, phi: float, state: np.ndarray) -> np.ndarray:  # pragma: no cover
    """x_k = phi x_(k-1) + drive_k from x_(-1) = state, per column: scipy.signal.lfilter([1], [1, -phi])
    does the same (the tests compare them), but importing scipy.signal costs every command a second."""
    out = np.empty_like(drive)
    x = state.copy()
    for k in range(drive.shape[0]):
        x = phi * x + drive[k]
        out[k] = x
    return out


def draw_errors(model: SensorModel, rng: np.random.Generator) -> SensorErrors:
    """The per-device constants: scale factors, misalignment and turn-on bias."""
    matrix = np.eye(3) + np.diag(rng.standard_normal(3) * model.scale_factor)
    off = rng.standard_normal((3, 3)) * model.misalignment_rad
    matrix += off - np.diag(np.diag(off))
    return SensorErrors(matrix, rng.standard_normal(3) * model.turn_on_bias)


def simulate(name: str, model: SensorModel, true_signal, duration: float, rng: np.random.Generator,
             errors: SensorErrors | None = None) -> SensorStream:
    """Sample true_signal(t) -> (K, 3) for `duration` seconds with every error of the model."""
    model.check(name)
    n = int(np.floor(duration * model.rate_hz)) + 1
    dt = 1.0 / model.rate_hz
    nominal = np.arange(n) * dt
    t = nominal + rng.standard_normal(n) * model.jitter_s
    t = np.maximum.accumulate(np.clip(t, 0.0, None))  # sampling instants never go backwards
    errors = errors or draw_errors(model, rng)
    walk = np.cumsum(rng.standard_normal((n, 3)) * model.bias_random_walk * np.sqrt(dt), axis=0)
    unstable = _gauss_markov(n, dt, model.bias_instability, model.bias_correlation_s, rng)
    white = rng.standard_normal((n, 3)) * model.noise_density * np.sqrt(model.rate_hz)
    values = true_signal(t) @ errors.matrix.T + errors.turn_on_bias + walk + unstable + white
    if model.resolution > 0:
        values = np.round(values / model.resolution) * model.resolution
    values = np.clip(values, -model.full_scale, model.full_scale)
    # Strictly increasing nanoseconds, as Android's are: at least 1 ns after the previous sample.
    k = np.arange(n)
    t_ns = np.maximum.accumulate(np.round(t * 1e9).astype(np.int64) - k) + k
    return SensorStream(name, t_ns, values)


def simulate_imu(trajectory: Trajectory, rng: np.random.Generator, gyroscope: SensorModel = GYROSCOPE,
                 accelerometer: SensorModel = ACCELEROMETER, magnetometer: SensorModel = MAGNETOMETER,
                 earth_field_ut: np.ndarray = EARTH_FIELD_UT) -> dict[str, SensorStream]:
    """The three streams of a trajectory, in device axes."""
    duration = trajectory.duration
    return {
        "gyroscope": simulate("gyroscope", gyroscope, trajectory.angular_velocity, duration, rng),
        "accelerometer": simulate("accelerometer", accelerometer, trajectory.specific_force, duration, rng),
        "magnetometer": simulate("magnetometer", magnetometer,
                                 lambda t: trajectory.orientation(t).inv().apply(np.tile(earth_field_ut, (len(t), 1))),
                                 duration, rng),
    }
