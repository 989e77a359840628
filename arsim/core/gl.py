"""The headless OpenGL context: moderngl over EGL (Mesa's llvmpipe on a CPU, the driver on a GPU)."""

from __future__ import annotations

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


def core_shader(name: str) -> str:
    """GLSL shared by the stages (arsim/core/shaders), e.g. anglemap.glsl."""
    return resources.files("arsim.core").joinpath("shaders", name).read_text(encoding="utf-8")
