"""The headless OpenGL context: moderngl over EGL (Mesa's llvmpipe on a CPU, the driver on a GPU)."""

from __future__ import annotations

import math
import numbers
from importlib import resources

from arsim.core.errors import ArsimError

# OpenGL 4.3 brings compute shaders and the timer queries the renderer and the profiler use.
REQUIRED_GL_VERSION = 430

_INSTALL_HINT = (
    "install EGL and Mesa (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri) "
    "or a GPU driver that provides libEGL"
)


def create_gl_context(require: int = REQUIRED_GL_VERSION):
    """A standalone moderngl context through EGL; a clear ArsimError where that is not possible."""
    try:
        import moderngl
    except ImportError as exc:  # a broken install, not a missing system library
        raise ArsimError(f"moderngl cannot be imported ({exc}); reinstall arsim: pip install -e .") from None
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:  # moderngl/glcontext raise plain Exceptions for a missing libEGL or display
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ArsimError(f"no headless OpenGL {require // 100}.{require % 100 // 10} context via EGL ({reason}); {_INSTALL_HINT}") from None
    return ctx


# A GL timer query's reading (moderngl's Query.elapsed: nanoseconds, read as a 32-bit unsigned integer) is a
# time only where it is positive and below 2^32 - 1: the driver clamps a result that does not fit (an interval
# over 4.29 s, or a negative one from a clock that stepped back) to 2^32 - 1, and 0 ns is no GPU work's time
# (a query that timed nothing). The others are dropped and counted, never reported as times.
TIMER_CLAMPED_NS = 2**32 - 1
TIMER_DROPPED = {
    "zero": "0 ns, a query that timed nothing",
    "clamped": "2^32 - 1 ns or more, a result that did not fit in 32 bits",
    "negative": "below 0 ns",
    "unavailable": "a query that could not be read, or not as a number",
}


def timer_ms(elapsed_ns) -> tuple[float | None, str | None]:
    """A timer query's reading as (milliseconds, None), or (None, why it is no time: a TIMER_DROPPED key)."""
    if isinstance(elapsed_ns, bool) or not isinstance(elapsed_ns, numbers.Real) or not math.isfinite(elapsed_ns):
        return None, "unavailable"  # (None, NaN, infinite, not a number)
    if elapsed_ns < 0:
        return None, "negative"
    if elapsed_ns == 0:
        return None, "zero"
    if elapsed_ns >= TIMER_CLAMPED_NS:
        return None, "clamped"
    return float(elapsed_ns) / 1e6, None


def query_ms(query) -> tuple[float | None, str | None]:
    """timer_ms of a moderngl timer query (after its `with` block); a query that cannot be read is unavailable."""
    try:
        elapsed = query.elapsed
    except Exception:  # (moderngl.Error from the driver, or a query object without a reading)
        return None, "unavailable"
    return timer_ms(elapsed)


def core_shader(name: str) -> str:
    """GLSL shared by the stages (arsim/core/shaders), e.g. anglemap.glsl."""
    return resources.files("arsim.core").joinpath("shaders", name).read_text(encoding="utf-8")
