"""What the camera sees: radiance views of the environment (an angle map at infinity) and, along the AR
path, of the table with its printed tag, through the OpenCV camera; and 8-bit camera frames of them
with the sensor model applied in the same pass. Rendered with moderngl (as the phone's GPU would), with
NumPy references the tests hold them to (environment_view_reference, camera.expose)."""

from __future__ import annotations

from importlib import resources

import cv2
import moderngl
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import core_shader, create_gl_context
from arsim.core.resample import extend_beyond_rim, sample_anglemap
from arsim.sensors.camera import ResponseCurve, SensorSettings, vignette
from arsim.sensors.table import Table, table_radiance_reference, upward_light


def pixel_rays(camera: CameraIntrinsics) -> np.ndarray:
    """Unit rays (H, W, 3) of every pixel centre in OpenCV camera axes."""
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    return camera.unproject(np.stack([u, v], axis=-1))


def environment_view_reference(probe: np.ndarray, camera: CameraIntrinsics, camera_to_world: Rotation,
                               position: np.ndarray | None = None, table: Table | None = None) -> np.ndarray:
    """Radiance (H, W, 3) float64 of the angle-map environment seen by the camera (bilinear), and of
    the table with its tag where the camera at `position` sees it."""
    rays = pixel_rays(camera)
    world = camera_to_world.apply(rays.reshape(-1, 3)).reshape(rays.shape)
    image = sample_anglemap(probe, world)
    if table is None:
        return image
    d = world.reshape(-1, 3)
    position = np.asarray(position, dtype=np.float64)
    down = (d[:, 1] < 0) & (position[1] > 0)
    t = np.where(down, -position[1] / np.where(down, d[:, 1], -1.0), 0.0)
    hits = position[[0, 2]] + t[:, None] * d[:, [0, 2]]
    surface = table_radiance_reference(table, upward_light(probe), hits)
    seen = down & np.isfinite(surface[:, 0])
    flat = image.reshape(-1, 3)
    flat[seen] = surface[seen]
    return image


def _shader(name: str) -> str:
    return resources.files("arsim.sensors").joinpath("shaders", name).read_text(encoding="utf-8")


def _with_alpha(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 -> (H, W, 4) with ones in the fourth channel."""
    return np.ascontiguousarray(np.concatenate([image, np.ones(image.shape[:2] + (1,), np.float32)], axis=-1))


def _scene_source(main: str, table: bool, defines: dict[str, int] | None = None) -> str:
    """GLSL of a shader that uses scene.glsl, with the table compiled in or not, and other defines."""
    lines = ["#version 430"] + (["#define TABLE"] if table else []) + [f"#define {k} {v}" for k, v in (defines or {}).items()]
    return "\n".join(lines) + "\n" + core_shader("anglemap.glsl") + _shader("scene.glsl") + _shader(main)


class EnvironmentRenderer:
    """Renders many views of one environment with moderngl; the probe texture is uploaded once."""

    def __init__(self, probe: np.ndarray, camera: CameraIntrinsics, ctx=None, table: Table | None = None):
        self.ctx = ctx or create_gl_context()
        self.camera = camera
        self.table = table
        self.table_light = upward_light(probe) if table is not None else np.zeros(3)
        sheet = table.paper_image if table is not None else np.zeros((1, 1), np.float32)
        self.paper = self.ctx.texture(sheet.shape[::-1], 1, np.ascontiguousarray(sheet).tobytes(), dtype="f4")
        self.paper.build_mipmaps()
        self.paper.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.paper.repeat_x = self.paper.repeat_y = False
        extended = np.ascontiguousarray(extend_beyond_rim(probe).astype(np.float32))
        n = probe.shape[0]
        # Four-channel float textures: llvmpipe fetches them measurably faster than three-channel ones.
        self.texture = self.ctx.texture((n, n), 4, _with_alpha(extended).tobytes(), dtype="f4")
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False  # clamp to edge
        self.program = self.ctx.program(vertex_shader=_shader("fullscreen.vert"),
                                        fragment_shader=_scene_source("environment_view.frag", table is not None))
        # Texture row y is image row y: the framebuffer then holds the image top row first, as read back.
        rays = np.ascontiguousarray(pixel_rays(camera).astype(np.float32))
        self.rays = self.ctx.texture((camera.width, camera.height), 4, _with_alpha(rays).tobytes(), dtype="f4")
        self.rays.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.vao = self.ctx.vertex_array(self.program, [])
        self.target = self.ctx.texture((camera.width, camera.height), 4, dtype="f4")
        self.fbo = self.ctx.framebuffer(color_attachments=[self.target])

    def render(self, camera_to_world: Rotation, position: np.ndarray | None = None) -> np.ndarray:
        """Radiance (H, W, 3) float32 of one view (from `position`, which matters for the table only)."""
        self.fbo.use()
        self._bind(self.program, camera_to_world, position)
        self.vao.render(mode=moderngl.TRIANGLES, vertices=3)
        data = np.frombuffer(self.fbo.read(components=4, dtype="f4"), dtype=np.float32)
        return np.ascontiguousarray(data.reshape(self.camera.height, self.camera.width, 4)[:, :, :3])

    def _bind(self, program, camera_to_world: Rotation, position: np.ndarray | None) -> None:
        self.texture.use(0)
        self.rays.use(1)
        self.paper.use(5)
        program["probe"].value = 0
        program["rays"].value = 1
        if self.table is not None:
            if position is None:
                raise ValueError("a view of the table needs the camera position")
            program["paper"].value = 5
            program["camera_position"].value = tuple(float(v) for v in position)
            program["table_half"].value = tuple(v / 2 for v in self.table.size_m)
            program["table_albedo"].value = tuple(self.table.albedo)
            program["table_light"].value = tuple(float(v) for v in self.table_light)
            program["paper_half"].value = self.table.paper_half_m
        # GLSL mat3 uniforms are column-major: pass the transpose of the row-major matrix.
        program["camera_to_world"].write(camera_to_world.as_matrix().T.astype("f4").tobytes())

    def release(self) -> None:
        for obj in (self.vao, self.program, self.fbo, self.target, self.texture, self.rays, self.paper):
            obj.release()


class CameraRenderer(EnvironmentRenderer):
    """8-bit camera frames made in one GL compute pass: the view, the sensor noise (hashed, so the GPU
    draws the same numbers as camera.pixel_normals), the gain and the response curve. camera.expose is
    its NumPy reference; only the radiance lookup differs (bilinear filtering with 8-bit weights)."""

    GROUP = 64  # pixels per work group (a row segment), as camera_frame.comp declares
    GUESS_BINS = 1024  # bins of the response curve's code guesses, as camera_frame.comp declares

    def __init__(self, probe: np.ndarray, camera: CameraIntrinsics, sensor: SensorSettings, response: ResponseCurve,
                 ctx=None, table: Table | None = None):
        super().__init__(probe, camera, ctx, table)
        self.sensor = sensor
        # The response curve: the codes from a table in one comparison where the curve allows it
        # (ResponseCurve.step_table: the same codes, 0.6 ms less of CPU a 640 x 480 frame), else a guess from a
        # table settled by the exact thresholds.
        one_step = response.step_table(self.GUESS_BINS)
        if one_step is not None:
            defines, tables = {"ONE_STEP": 1}, {"guess_table": one_step[0], "step_table": one_step[1]}
        else:
            guesses, steps = response.guess_table(self.GUESS_BINS)
            defines, tables = {"SETTLE_STEPS": steps}, {"guess_table": guesses, "thresholds": response.thresholds_float32()}
        self.frame_program = self.ctx.compute_shader(_scene_source("camera_frame.comp", table is not None, defines))
        # The vignetting rides in the rays' fourth channel: one texel fetch per pixel for both.
        falloff = vignette(camera.height, camera.width, sensor.vignetting).astype(np.float32)
        self.rays.write(np.dstack([pixel_rays(camera).astype(np.float32), falloff]).tobytes())
        for name, values in tables.items():
            self.frame_program[name].write(values.tobytes())
        self.frame_program["read_noise_var"].value = sensor.read_noise_e**2
        self.frame_program["width"].value = camera.width
        self.frame_program["height"].value = camera.height
        self.codes = self.ctx.buffer(reserve=camera.width * camera.height * 4)  # RGBA bytes per pixel

    def capture(self, camera_to_world: Rotation, exposure_s: float, iso: float, key: int,
                position: np.ndarray | None = None) -> np.ndarray:
        """The 8-bit frame (H, W, 3) uint8 of one view; key: camera.noise_key of the frame."""
        p, s = self.frame_program, self.sensor
        self._bind(p, camera_to_world, position)
        # The same float32 constants as camera.expose.
        p["electrons_per_radiance"].value = float(np.float32(exposure_s * s.sensitivity * s.full_well_e))
        p["gain"].value = float(np.float32(iso / s.base_iso / s.full_well_e))
        p["noise_key"].value = int(key)
        self.codes.bind_to_storage_buffer(0)
        p.run(-(-self.camera.width // self.GROUP), self.camera.height)
        # Every invocation's store done before the read-back: a barrier, then a finish, as a frame whose
        # write raced the read would differ from the same seed's in a few pixels.
        self.ctx.memory_barrier()
        self.ctx.finish()
        data = np.frombuffer(self.codes.read(), dtype=np.uint8).reshape(self.camera.height, self.camera.width, 4)
        # (contiguous: every later copy of the RGB view, as numpy makes it, took 2 ms a 640 x 480 frame)
        return cv2.cvtColor(data, cv2.COLOR_RGBA2RGB)

    def release(self) -> None:
        for obj in (self.frame_program, self.codes):
            obj.release()
        super().release()
