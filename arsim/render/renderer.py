"""The renderer's GL passes (moderngl): virtual objects into an HDR colour target and a mask (thesis
5.1 step 4-6), then the masked tone mapping over the camera image (step 7).

Images come back with row 0 at the top (OpenCV's convention); GL's framebuffer rows are bottom-up.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics, gl_projection_from_intrinsics, gl_view_from_opencv_pose
from arsim.core.gl import core_shader, create_gl_context
from arsim.core.resample import extend_beyond_rim
from arsim.render.meshes import Mesh
from arsim.render.shading import TONEMAP_LUMA


def _shader(name: str) -> str:
    return resources.files("arsim.render").joinpath("shaders", name).read_text(encoding="utf-8")


def _source(name: str, defines: list[str]) -> str:
    header = "#version 430\n" + "".join(f"#define {d}\n" for d in defines)
    return header + (core_shader("anglemap.glsl") if name.endswith(".frag") else "") + _shader(name)


@dataclass
class Material:
    """Phong coefficients and the exponent whose reflection map the specular part reads; optional
    ambient-occlusion light map (second UV set) and tangent-space normal map (first UV set), as
    (H, W, 3) float arrays, row 0 at the top (v = 1)."""

    kd: tuple[float, float, float] = (0.6, 0.6, 0.6)
    ks: tuple[float, float, float] = (0.3, 0.3, 0.3)
    exponent: float = 80.0
    light_map: np.ndarray | None = None
    normal_map: np.ndarray | None = None


@dataclass
class SceneObject:
    mesh: Mesh
    material: Material
    model: np.ndarray = field(default_factory=lambda: np.eye(4))  # object to world


class Renderer:
    """Renders virtual objects lit by angle maps (maps[1.0]: irradiance, maps[s]: reflection, s > 1)."""

    def __init__(self, camera: CameraIntrinsics, maps: dict[float, np.ndarray], ctx=None, debug: bool = False,
                 near: float = 0.02, far: float = 50.0):
        self.ctx = ctx or create_gl_context()
        self.camera, self.debug = camera, debug
        self.projection = gl_projection_from_intrinsics(camera, near, far)
        self.maps = {s: self._map_texture(m) for s, m in maps.items()}
        size = (camera.width, camera.height)
        # HDR colour and mask: a power of two on each side, so that their mip chains end in the exact mean
        # (an odd level drops a row or column); the frame occupies the lower-left corner.
        padded = tuple(1 << int(np.ceil(np.log2(k))) for k in size)
        self.hdr = self.ctx.texture(padded, 4, dtype="f2")
        self.mask = self.ctx.texture(padded, 2, dtype="f2")  # the mask, and log(delta + L_w) where it is set
        attachments = [self.hdr, self.mask]
        if debug:
            self.debug_targets = [self.ctx.texture(padded, 4, dtype="f4") for _ in range(2)]
            attachments += self.debug_targets
        self.fbo = self.ctx.framebuffer(attachments, self.ctx.depth_renderbuffer(padded))
        self.objects: list[tuple[SceneObject, object, object, dict]] = []
        self.output = self.ctx.texture(size, 4, dtype="f1")
        self.output_fbo = self.ctx.framebuffer([self.output])
        self.tonemappers = {}

    def _map_texture(self, anglemap: np.ndarray):
        data = np.ascontiguousarray(extend_beyond_rim(anglemap).astype(np.float32))
        texture = self.ctx.texture(data.shape[:2][::-1], 3, data.tobytes(), dtype="f4")
        texture.repeat_x = texture.repeat_y = False
        return texture

    def _image_texture(self, image: np.ndarray):
        """A float RGB texture of an image whose row 0 is its top (GL's v = 1)."""
        data = np.ascontiguousarray(np.asarray(image, dtype=np.float32)[::-1])
        texture = self.ctx.texture(data.shape[:2][::-1], 3, data.tobytes(), dtype="f4")
        texture.build_mipmaps()
        return texture

    def add(self, obj: SceneObject) -> None:
        m = obj.material
        if m.exponent not in self.maps:
            raise ValueError(f"no reflection map for exponent {m.exponent:g}; maps for: {sorted(self.maps)}")
        defines = (["LIGHT_MAP"] if m.light_map is not None else []) + (["NORMAL_MAP"] if m.normal_map is not None else [])
        defines += ["DEBUG"] if self.debug else []
        program = self.ctx.program(vertex_shader=_source("object.vert", defines), fragment_shader=_source("object.frag", defines))
        vbo = self.ctx.buffer(obj.mesh.interleaved().tobytes())
        ibo = self.ctx.buffer(obj.mesh.indices.astype(np.uint32).tobytes())
        sizes = {"in_position": 3, "in_normal": 3, "in_tangent": 3, "in_uv": 2, "in_uv2": 2}
        used = [n for n in sizes if n in program]  # the compiler drops what a variant does not read
        layout = " ".join(f"{k}f" if n in used else f"{k}x4" for n, k in sizes.items())
        vao = self.ctx.vertex_array(program, [(vbo, layout, *used)], ibo)
        textures = {"light_map": self._image_texture(m.light_map) if m.light_map is not None else None,
                    "normal_map": self._image_texture(m.normal_map) if m.normal_map is not None else None}
        self.objects.append((obj, program, vao, textures))

    def render_objects(self, rotation: Rotation, translation: np.ndarray) -> None:
        """Steps 4-6: the objects into the HDR colour and the mask, seen from the OpenCV world-to-camera
        pose (x_cam = R x_world + t)."""
        view = gl_view_from_opencv_pose(rotation, translation)
        eye = -rotation.as_matrix().T @ np.asarray(translation, dtype=np.float64)
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.fbo.viewport = (0, 0, self.camera.width, self.camera.height)
        self.ctx.enable(self.ctx.DEPTH_TEST)
        for obj, program, vao, textures in self.objects:
            normal_matrix = np.linalg.inv(obj.model[:3, :3]).T
            program["model"].write(obj.model.T.astype("f4").tobytes())
            program["view_projection"].write((self.projection @ view).T.astype("f4").tobytes())
            program["normal_matrix"].write(normal_matrix.T.astype("f4").tobytes())
            program["kd"].value = tuple(obj.material.kd)
            program["ks"].value = tuple(obj.material.ks)
            program["eye"].value = tuple(eye)
            units = [("irradiance_map", self.maps[1.0]), ("reflection_map", self.maps[obj.material.exponent])]
            units += [(name, tex) for name, tex in textures.items() if tex is not None]
            for unit, (name, tex) in enumerate(units):
                tex.use(unit)
                program[name].value = unit
            vao.render()
        self.ctx.disable(self.ctx.DEPTH_TEST)

    def _tonemapper(self, log_average: bool):
        if log_average not in self.tonemappers:
            defines = ["LOG_AVERAGE"] if log_average else []
            program = self.ctx.program(vertex_shader=_source("fullscreen.vert", []), fragment_shader=_source("tonemap.frag", defines))
            self.tonemappers[log_average] = (program, self.ctx.vertex_array(program, []))
        return self.tonemappers[log_average]

    def top_level(self) -> int:
        return int(np.log2(max(self.hdr.width, self.hdr.height)))

    def tonemap(self, background: np.ndarray, key: float = 0.18, white: float = 2.0, log_average: bool = False) -> np.ndarray:
        """Step 7: Reinhard's operator on the masked pixels over the camera frame (H, W, 3) uint8, with the
        masked pixels' mean luminance or (log_average) their log-average; the 8-bit result (H, W, 3),
        row 0 at the top."""
        self.tonemap_pass(background, key, white, log_average)
        return self.read_output()

    def tonemap_pass(self, background: np.ndarray, key: float = 0.18, white: float = 2.0, log_average: bool = False) -> None:
        """Step 7 into the output target, without reading it back."""
        self.hdr.build_mipmaps()  # its alpha is the mask's coverage
        if log_average:
            self.mask.build_mipmaps()  # its second channel: log(delta + L_w) of the masked pixels
        program, vao = self._tonemapper(log_average)
        frame = self.ctx.texture((self.camera.width, self.camera.height), 3, np.ascontiguousarray(background).tobytes())
        for unit, (name, tex) in enumerate([("hdr", self.hdr), ("mask", self.mask), ("background", frame)]):
            tex.use(unit)
            program[name].value = unit
        program["key"].value, program["white"].value = key, white
        program["top_level"].value = float(self.top_level())
        self.output_fbo.use()
        vao.render(vertices=3)
        frame.release()

    def _read(self, texture, components: int, dtype: str, level: int = 0) -> np.ndarray:
        """A texture level as an image, row 0 at the top; level 0 cropped to the frame."""
        w, h = max(texture.width >> level, 1), max(texture.height >> level, 1)
        np_dtype = {"f1": np.uint8, "f2": np.float16, "f4": np.float32}[dtype]
        data = np.frombuffer(texture.read(level=level), dtype=np_dtype).reshape(h, w, components)
        if level == 0:
            data = data[:self.camera.height, :self.camera.width]
        return data[::-1].astype(np.float32 if dtype != "f1" else np.uint8)

    def read_output(self) -> np.ndarray:
        """The tone-mapped frame (H, W, 3) uint8 of the last tonemap_pass."""
        return self._read(self.output, 4, "f1")[..., :3]

    def read_hdr(self) -> np.ndarray:
        return self._read(self.hdr, 4, "f2")[..., :3]

    def read_mask(self) -> np.ndarray:
        return self._read(self.mask, 2, "f2")[..., 0]

    def read_debug(self) -> tuple[np.ndarray, np.ndarray]:
        """(normal (H, W, 4): the shaded normal and the light-map value in w, incident (H, W, 4))."""
        return tuple(self._read(t, 4, "f4") for t in self.debug_targets)

    def mip_average(self, log_average: bool = False) -> float:
        """The average luminance of the masked pixels as the tone mapper reads it from the mip tops (after
        a tonemap pass with the same log_average)."""
        top = self.top_level()
        mean = self._read(self.hdr, 4, "f2", top)[0, 0]
        if log_average:
            return float(np.exp(self._read(self.mask, 2, "f2", top)[0, 0, 1] / max(mean[3], 1e-12)))
        return float(mean[:3] @ TONEMAP_LUMA / max(mean[3], 1e-12))
