"""The headless GL context: it renders where EGL exists, and says what to install where it does not."""

import numpy as np
import pytest

from arsim.core.errors import ArsimError
from arsim.core.gl import create_gl_context


def test_context_clears_and_reads_back_a_float_framebuffer():
    ctx = create_gl_context()
    assert ctx.version_code >= 430
    fbo = ctx.simple_framebuffer((8, 4), components=4, dtype="f4")
    fbo.use()
    fbo.clear(0.25, 0.5, 1.0, 1.0)
    pixels = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32).reshape(4, 8, 4)
    np.testing.assert_array_equal(pixels[..., :3], np.broadcast_to([0.25, 0.5, 1.0], (4, 8, 3)))
    ctx.release()


def test_missing_egl_gives_one_line_saying_what_to_install(monkeypatch):
    import moderngl

    def no_egl(**kwargs):
        raise Exception("libEGL.so: cannot open shared object file: No such file or directory")

    monkeypatch.setattr(moderngl, "create_standalone_context", no_egl)
    with pytest.raises(ArsimError) as info:
        create_gl_context()
    message = str(info.value)
    assert "\n" not in message and "libEGL.so" in message and "apt-get install libegl1" in message
