"""What the camera sees of the environment: radiance images of the angle map through a pinhole camera,
rendered with moderngl (as the phone's GPU would) and with a NumPy reference that tests hold it to."""

from __future__ import annotations

from importlib import resources

import moderngl
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.resample import extend_beyond_rim, sample_anglemap


def pixel_rays(camera: CameraIntrinsics) -> np.ndarray:
    """Unit rays (H, W, 3) of every pixel centre in OpenCV camera axes."""
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    return camera.unproject(np.stack([u, v], axis=-1))


def environment_view_reference(probe: np.ndarray, camera: CameraIntrinsics, camera_to_world: Rotation) -> np.ndarray:
    """Radiance (H, W, 3) float64 of the angle-map environment seen by the camera (bilinear)."""
    rays = pixel_rays(camera)
    world = camera_to_world.apply(rays.reshape(-1, 3)).reshape(rays.shape)
    return sample_anglemap(probe, world)


def _shader(name: str) -> str:
    return resources.files("arsim.sensors").joinpath("shaders", name).read_text(encoding="utf-8")


class EnvironmentRenderer:
    """Renders many views of one environment with moderngl; the probe texture is uploaded once."""

    def __init__(self, probe: np.ndarray, camera: CameraIntrinsics, ctx=None):
        self.ctx = ctx or create_gl_context()
        self.camera = camera
        extended = np.ascontiguousarray(extend_beyond_rim(probe).astype(np.float32))
        n = probe.shape[0]
        self.texture = self.ctx.texture((n, n), 3, extended.tobytes(), dtype="f4")
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False  # clamp to edge
        self.program = self.ctx.program(vertex_shader=_shader("fullscreen.vert"),
                                        fragment_shader=_shader("environment_view.frag"))
        rays = np.ascontiguousarray(pixel_rays(camera)[::-1].astype(np.float32))  # GL rows run bottom-up
        self.rays = self.ctx.texture((camera.width, camera.height), 3, rays.tobytes(), dtype="f4")
        self.rays.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.vao = self.ctx.vertex_array(self.program, [])
        self.target = self.ctx.texture((camera.width, camera.height), 4, dtype="f4")
        self.fbo = self.ctx.framebuffer(color_attachments=[self.target])

    def render(self, camera_to_world: Rotation) -> np.ndarray:
        """Radiance (H, W, 3) float32 of one view."""
        self.fbo.use()
        self.texture.use(0)
        self.rays.use(1)
        self.program["probe"].value = 0
        self.program["rays"].value = 1
        # GLSL mat3 uniforms are column-major: pass the transpose of the row-major matrix.
        self.program["camera_to_world"].write(camera_to_world.as_matrix().T.astype("f4").tobytes())
        self.vao.render(mode=moderngl.TRIANGLES, vertices=3)
        data = np.frombuffer(self.fbo.read(components=4, dtype="f4"), dtype=np.float32)
        image = data.reshape(self.camera.height, self.camera.width, 4)[::-1, :, :3]
        return np.ascontiguousarray(image)

    def release(self) -> None:
        for obj in (self.vao, self.program, self.fbo, self.target, self.texture, self.rays):
            obj.release()
