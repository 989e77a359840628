"""The renderer's GL passes (moderngl), thesis 5.1 steps 4-7: the camera frame as the background, the
virtual objects into an HDR colour target whose alpha is the mask, the masked tone mapping, and the
overlay.

The objects are drawn into a tile: render targets a power of two on each side, just large enough for
the objects' rectangle on the screen (their bounding boxes, projected), with the frame's viewport shifted
so that the rectangle's corner lands on the tile's. Clearing the tile, the tone mapper's average and the
tone mapping then cost what the objects cover, not what the frame does (on llvmpipe, a 1280 x 720
RGBA16F clear and mip chain take 5 ms; a fullscreen pass 2 ms): each runs on the objects' own
rectangles (merge_rects). The average is summed in blocks into a target AVERAGE_BLOCK times smaller on
each side, whose texels over the blocks' box the tone mapper's vertex shader sums (average_sum.glsl).

Images come back with row 0 at the top (OpenCV's convention); GL's framebuffer rows are bottom-up.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from importlib import resources

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics, gl_projection_from_intrinsics, gl_view_from_opencv_pose
from arsim.core.errors import ArsimError
from arsim.core.gl import core_shader, create_gl_context
from arsim.core.resample import extend_beyond_rim
from arsim.lighting.bases import parse_basis
from arsim.lighting.mapset import MapSet
from arsim.render.meshes import Mesh


def _shader(name: str) -> str:
    return resources.files("arsim.render").joinpath("shaders", name).read_text(encoding="utf-8")


def _bases_glsl() -> str:
    return resources.files("arsim.lighting").joinpath("shaders", "bases.glsl").read_text(encoding="utf-8")


def _with_alpha(image: np.ndarray, dtype) -> np.ndarray:
    """An (H, W, 3) image as contiguous (H, W, 4) with alpha 1: llvmpipe samples four-channel textures
    faster than three-channel ones (the same values; README: AR session, Rendering speed)."""
    out = np.ones((*image.shape[:2], 4), dtype)
    out[..., :3] = image
    return out


def _place(program, model: np.ndarray) -> None:
    """A mesh object's program told where it stands: the model matrix, its normal matrix and, for a
    ray-cast torus, its inverse (the ray into object space)."""
    program["model"].write(model.T.astype("f4").tobytes())
    program["normal_matrix"].write(np.linalg.inv(model[:3, :3]).astype("f4").tobytes())  # (inverse transpose, column-major)
    if "object_from_world" in program:
        program["object_from_world"].write(np.linalg.inv(model).T.astype("f4").tobytes())


def _source(name: str, defines: list[str]) -> str:
    header = "#version 430\n" + "".join(f"#define {d}\n" for d in defines)
    shared = core_shader("anglemap.glsl") if name.endswith(".frag") else ""
    if name in ("rects.vert", "average_sum.frag"):
        shared += _shader("average_sum.glsl")
    if name.endswith(".frag") and "INM" in defines:
        shared += _bases_glsl()
    return header + shared + _shader(name)


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
    method: str = ""  # whose maps light it ("": the renderer's default method)
    # Irradiance normal mapping: a directional light map (H, W, count, 3), per texel of the second UV set
    # the coefficients of the irradiance in `basis` (e.g. "modh6"), evaluated with the normal map's
    # tangent-space normal; it replaces the irradiance map (and the AO light map) in the diffuse part.
    # inm_terms: the spec's level of detail (listing 2.2), the leading terms summed (None: all).
    directional_map: np.ndarray | None = None
    basis: str = ""
    inm_terms: int | None = None
    # An irradiance volume (spec 1.9, for objects that move): (coefficients (X, Y, Z, 9, 3) of the
    # convolved SH in world axes at grid points spanning the box, low (3,), high (3,)); it replaces the
    # irradiance map in the diffuse part.
    irradiance_volume: tuple | None = None
    volume_lit: bool = False  # to be lit through the scene's irradiance volume (content.light_objects bakes it)
    # Precomputed radiance transfer (README: Precomputed radiance transfer): the variant (lighting.prt.VARIANTS)
    # and per point the (count, order^2) matrices from the light's SH to the variant's coefficients, per vertex
    # of the mesh (V, count, L2) or per texel of the light map (second UV set, row 0 at the top) (H, W, count,
    # L2); prt_compressed: the same as CPCA (lighting.prt.Compressed), relit in its place. Renderer.relight
    # sets the coefficients from the light (they are 0 until it is called); the diffuse part is then the
    # variant's basis at the normal map's normal, as for a directional light map.
    prt_variant: str = ""
    prt_matrices: np.ndarray | None = None
    prt_compressed: object = None
    prt_light: np.ndarray | None = None  # the light's SH (order^2, 3) it is relit with when added (None: zeros)
    # Metallic-roughness (README: GGX materials): model "ggx" takes base_color, metallic and roughness
    # instead of kd, ks and the exponent: diffuse (1 - metallic) base_color times what the diffuse part
    # gives (the irradiance map, a light map, a volume...), specular the GGX prefiltered radiance of the light
    # (ggx_chain: the cube map's levels, lighting.ggx.prefilter_ggx, set by content.light_objects) times the
    # split sum F0 A + B (lighting.ggx.brdf_lut).
    model: str = "phong"
    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    ggx_chain: list | None = None


def box_corners(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(8, 3) the corners of the axis-aligned box low..high."""
    return np.array([[(low, high)[(k >> a) & 1][a] for a in range(3)] for k in range(8)], dtype=np.float64)


@dataclass(frozen=True)
class Orbit:
    """How an object moves: round a circle on the table about where it stands, counter-clockwise seen
    from above, at the start on the circle's +z side."""

    radius: float  # world units
    period_s: float  # one turn

    def offset(self, time_s: float) -> np.ndarray:
        """(3,) the object's world displacement from where it stands at time_s."""
        angle = 2.0 * np.pi * time_s / self.period_s
        return self.radius * np.array([np.sin(angle), 0.0, np.cos(angle)])


@dataclass
class SceneObject:
    mesh: Mesh
    material: Material
    model: np.ndarray = field(default_factory=lambda: np.eye(4))  # object to world
    # Coarser meshes of the same surface for when it is far away, finest first, each with its largest
    # departure from the surface (object units); the mesh itself counts as exact.
    lods: tuple[tuple[Mesh, float], ...] = ()
    # A sphere of this radius (object units) about the object's origin, the mesh its tessellation: without
    # light and normal maps it is drawn as a camera-facing quad that the fragment shader ray-casts (the
    # exact outline and normals, from two triangles: llvmpipe spends about a microsecond per triangle).
    sphere: float | None = None
    # A torus (major and minor radius, object units; resting on y = 0 about the y axis), the mesh its
    # tessellation, and a coarse mesh that holds it (content.torus_proxy): without PRT or a directional light
    # map it is drawn as that mesh's faces, through which the fragment shader ray-casts the torus (the exact
    # outline, normals and UVs from 256 triangles, where the fine mesh's small triangles cost llvmpipe its
    # pixels shaded many times over).
    torus: tuple[float, float, Mesh] | None = None
    # For baking its directional light map (irradiance normal mapping): its light map's texels in world
    # space (a lighting.bases.lightmap.Surface), and its distance function in world space (what it
    # occludes); None where it has none.
    lightmap_surface: object = None  # () -> Surface
    distance: object = None  # (points (..., 3)) -> (...)
    mesh_occludes: bool = False  # it occludes by its mesh (ray casts): a mesh file's object, with no distance function
    orbit: Orbit | None = None  # it moves (the model places it at the orbit's centre); None: it stands still
    transfer: object = None  # lighting = prt-...: its PRT settings (render.transfer.PrtSettings), computed by light_objects

    def corners(self) -> np.ndarray:
        """(8, 3) the world corners of its mesh's bounding box (where it stands)."""
        box = box_corners(self.mesh.positions.min(axis=0), self.mesh.positions.max(axis=0))
        return (np.hstack([box, np.ones((8, 1))]) @ self.model.T)[:, :3]

    def swept_corners(self) -> np.ndarray:
        """(8, 3) the corners of a world box that holds it wherever its orbit takes it."""
        corners = self.corners()
        if self.orbit is None:
            return corners
        reach = np.array([self.orbit.radius, 0.0, self.orbit.radius])
        return box_corners(corners.min(axis=0) - reach, corners.max(axis=0) + reach)


# Level of detail: the coarsest mesh whose departure from the surface stays under this many pixels on the
# screen (where the object is nearest). llvmpipe shades pixels in blocks, so a triangle of a few pixels
# costs many times its area: the default torus at 0.8 m takes 6 ms with its finest mesh, 2.6 with a
# coarse one. Shading interpolates the true normals, so the mesh shows only in the outline.
LOD_ERROR_PX = 0.5


@dataclass
class _Drawable:
    program: object
    vaos: list  # per mesh: the object's mesh, then its lods
    errors: np.ndarray  # per mesh: its largest departure from the surface, world units
    units: list  # the textures, in their units: irradiance map, reflection map, light map, normal map
    corners: np.ndarray  # (8, 4) the world bounding box's corners, homogeneous
    texel_world: dict  # per texture: world length per texel along the surface (median over triangles)
    sphere: tuple[np.ndarray, float] | None = None  # a ray-cast sphere's world centre and radius
    orbit: Orbit | None = None
    model: np.ndarray | None = None  # where it stands (object to world), for one that moves
    prt: tuple | None = None  # (the material, the coefficients' buffer (vertex) or texture array (texel))


# The tone mapper's average is summed in blocks of this many pixels a side, over the objects' rectangles
# only, into a target this many times smaller on each side than the tile, whose texels the tone mapper sums:
# on llvmpipe the RGBA16F mip chain of a whole tile took 3 ms a frame (median; 13 at worst), the tile
# mostly the space between the objects; the blocks and a mip chain of their target took 0.5-1 ms (8
# measured a little faster than 4), the chain alone 0.5-0.7 ms whatever its size (a blit per level), and
# the one-fragment sum instead took the step from 2.5 to 1.9-2.0 times its floor (benchmarks/bench_render.py).
AVERAGE_BLOCK = 8


@dataclass
class _Tile:
    """The render targets of one tile size: HDR colour (its alpha the mask: 1 where an object was drawn),
    depth, and with debug the shading vectors; and the tone mapper's average target (a texel per
    AVERAGE_BLOCK² pixels: the block's mean luminance or log, its coverage) and the blocks' box in it."""

    hdr: object
    fbo: object
    clear_fbo: object  # the depth (and the debug targets): what clears fast
    zeros: bytes  # an HDR tile of zeros
    average: object
    average_fbo: object
    debug: list = field(default_factory=list)
    box: tuple = (0, 0, 0, 0)  # x0, y0, x1, y1 (exclusive): the last average pass's blocks, in the target's texels
    dirty: list = field(default_factory=list)  # the rectangles (x, y, w, h) written since the tile was zeroed

    def clear(self, rects: list[tuple[int, int, int, int]]) -> None:
        """Clear for a frame whose objects lie in rects (tile pixels): the rectangles the last frame wrote,
        so that the whole tile is zero again (a tile's pixels are written only inside its frame's
        rectangles). llvmpipe clears 64-bit pixels (RGBA16F) through a slow path, 3 to 5 times what
        uploading zeros takes: the HDR colour gets zeros uploaded, the depth a clear; and over the
        objects' own rectangles, not the space between them that their union holds."""
        for x, y, w, h in self.dirty:
            self.clear_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=(x, y, w, h))
            self.hdr.write(memoryview(self.zeros)[:w * h * 8], viewport=(x, y, w, h))
        width, height = self.hdr.size
        self.dirty = [(x, y, min(w, width - x), min(h, height - y)) for x, y, w, h in rects if x < width and y < height]


def texel_length(mesh: Mesh, uvs: np.ndarray, texture_size: int) -> float:
    """The world length a texel of a square-ish texture of texture_size texels spans on the mesh: the
    median over its triangles of sqrt(world area / UV area) / texture_size."""
    p, t = mesh.positions[mesh.indices].astype(np.float64), uvs[mesh.indices].astype(np.float64)
    world = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    uv = np.abs(d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1])
    ok = (uv > 0) & (world > 0)
    return float(np.median(np.sqrt(world[ok] / uv[ok]))) / texture_size if ok.any() else 0.0


# The overlay's box: 55 % opaque where no text covers it (overlay.frag takes the larger of this and the coverage).
OVERLAY_BOX_ALPHA = 140


def overlay_coverage(lines: Sequence[str], frame_height: int) -> np.ndarray:
    """The overlay's text as its coverage (h, w) uint8, row 0 at the top: white text (OpenCV's Hershey font,
    anti-aliased) in a box; sized to the frame's height. Step 7 uploads this and overlay.frag makes the colour
    and alpha of overlay_image from it."""
    scale = max(frame_height / 720.0 * 0.6, 0.35)  # (below 0.35 the Hershey font is not legible)
    thickness = max(int(round(scale * 1.6)), 1)
    sizes = [cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, scale, thickness) for line in lines]
    line_height = max((s[0][1] + s[1] for s in sizes), default=1) + 4
    pad = line_height // 3
    coverage = np.zeros((len(lines) * line_height + 2 * pad, max((s[0][0] for s in sizes), default=1) + 2 * pad), np.uint8)
    for k, line in enumerate(lines):
        baseline = pad + (k + 1) * line_height - sizes[k][1] - 2
        cv2.putText(coverage, line, (pad, baseline), cv2.FONT_HERSHEY_SIMPLEX, scale, 255, thickness, cv2.LINE_AA)
    return coverage


def overlay_image(lines: Sequence[str], frame_height: int) -> np.ndarray:
    """The overlay as an RGBA image (h, w, 4) uint8, row 0 at the top: its text (overlay_coverage) white on a
    black box at OVERLAY_BOX_ALPHA opacity; what step 7 blends over the frame."""
    coverage = overlay_coverage(lines, frame_height)
    return np.dstack([coverage, coverage, coverage, np.maximum(coverage, OVERLAY_BOX_ALPHA)])


# Rectangles are merged where their bounding rectangle is at most this many times the area they cover:
# each rectangle costs every frame a clear and an upload of zeros (0.05-0.1 ms on llvmpipe), and a row of
# objects side by side is as cheap drawn as one.
MERGE_SLACK = 1.25


def merge_rects(rects: Sequence[tuple[int, int, int, int]], slack: float = MERGE_SLACK) -> list[tuple[int, int, int, int]]:
    """Rectangles (x, y, w, h), two at a time replaced by their bounding rectangle where its area is at
    most slack times the area the two cover (the first such pair in order, until none is left): what
    covers every pixel the given ones do."""
    out = [tuple(int(v) for v in r) for r in rects]
    merged = True
    while merged:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                (ax, ay, aw, ah), (bx, by, bw, bh) = out[i], out[j]
                x0, y0, x1, y1 = min(ax, bx), min(ay, by), max(ax + aw, bx + bw), max(ay + ah, by + bh)
                overlap = max(min(ax + aw, bx + bw) - max(ax, bx), 0) * max(min(ay + ah, by + bh) - max(ay, by), 0)
                if (x1 - x0) * (y1 - y0) <= slack * (aw * ah + bw * bh - overlap):
                    out[i] = (x0, y0, x1 - x0, y1 - y0)
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return out


def _power_of_two(n: int, least: int = 16) -> int:
    return max(1 << int(np.ceil(np.log2(max(n, 1)))), least)


class Renderer:
    """Renders virtual objects lit by angle maps: per map set (one per method), its irradiance map (s = 1)
    and reflection maps (s > 1); a material takes its method's maps. Materials that name no method take
    `method` (default: the first set's)."""

    def __init__(self, camera: CameraIntrinsics, maps: MapSet | Iterable[MapSet], ctx=None, debug: bool = False,
                 near: float = 0.02, far: float = 50.0, method: str | None = None):
        self.ctx = ctx or create_gl_context()
        self.camera, self.debug, self.near = camera, debug, near
        self.projection = gl_projection_from_intrinsics(camera, near, far)
        sets = [maps] if isinstance(maps, MapSet) else list(maps)
        if not sets or not all(isinstance(m, MapSet) for m in sets):
            raise TypeError("Renderer takes MapSets (arsim.lighting.mapset), one per method")
        self.maps = {(m.method, s): self._map_texture(a) for m in sets for s, a in m.maps.items()}
        self.default_method = sets[0].method if method is None else method
        self.objects: list[_Drawable] = []
        self.corners = np.zeros((0, 8, 4))  # per object, its world bounding box's corners
        self.tiles: dict[tuple[int, int], _Tile] = {}
        self.tile: _Tile | None = None  # the last render_objects' tile; None when nothing was in view
        self.rect: tuple[int, int, int, int] | None = None  # its rectangle in the frame: x, y (GL, from the bottom), w, h
        self.rects: list[tuple[int, int, int, int]] = []  # the objects' own rectangles in it (merge_rects)
        # The output: the camera frame written in (step 4), the tone-mapped objects drawn over it (step 6).
        # Its rows run from the image's top, as the camera delivers them (the passes that draw into it
        # flip GL's bottom-up rows instead of a copy of each frame), and it is RGBA (llvmpipe writes and
        # draws into 3-byte pixels through a slow path, 2-3 times the time).
        self.output = self.ctx.texture((camera.width, camera.height), 4, dtype="f1")
        self._rgba = np.empty((camera.height, camera.width, 4), np.uint8)
        self.output_fbo = self.ctx.framebuffer([self.output])
        self.tonemappers = {}
        self._sum_program = None
        self._rect_arrays = {}  # per program (by id: each is kept in tonemappers), the rectangles' buffer and vertex array
        self._ggx_cache = {}  # GGX materials' prefiltered cube maps (per chain) and the split sum's table
        self._cube_writer = None
        self.overlay_program = None
        self.overlay_box = None  # the overlay's pixels (a slice of the image) after overlay_pass

    def _map_texture(self, anglemap: np.ndarray):
        data = _with_alpha(extend_beyond_rim(anglemap), np.float32)
        texture = self.ctx.texture(data.shape[:2][::-1], 4, data.tobytes(), dtype="f4")
        texture.repeat_x = texture.repeat_y = False
        return texture

    def _image_texture(self, image: np.ndarray):
        """A half-float RGBA texture of an image whose row 0 is its top (GL's v = 1): a light or normal map,
        values within [0, 1], where half floats keep 2.4e-4 of a value and halve what each fetch reads."""
        data = _with_alpha(np.asarray(image)[::-1], np.float16)
        texture = self.ctx.texture(data.shape[:2][::-1], 4, data.tobytes(), dtype="f2")
        texture.build_mipmaps()
        return texture

    def _coefficient_texture(self, coefficients: np.ndarray):
        """A float RGB texture array, a layer per basis coefficient, of an (H, W, count, 3) light map whose
        row 0 is its top."""
        layers = np.ascontiguousarray(np.moveaxis(np.asarray(coefficients, dtype=np.float32)[::-1], 2, 0))
        texture = self.ctx.texture_array((layers.shape[2], layers.shape[1], layers.shape[0]), 3, layers.tobytes(), dtype="f4")
        texture.build_mipmaps()
        return texture

    def _volume_textures(self, volume: np.ndarray) -> list:
        """Nine float RGB 3D textures (clamped at the box's faces), one per SH coefficient, of an (X, Y, Z, 9,
        3) volume."""
        out = []
        for k in range(9):
            data = np.ascontiguousarray(np.transpose(volume[:, :, :, k, :], (2, 1, 0, 3)).astype(np.float32))
            texture = self.ctx.texture3d(volume.shape[:3], 3, data.tobytes(), dtype="f4")
            texture.repeat_x = texture.repeat_y = texture.repeat_z = False
            out.append(texture)
        return out

    def add(self, obj: SceneObject) -> None:
        """Compile the object's shader variant, upload its geometry and textures, and keep it to draw."""
        m = obj.material
        method = m.method or self.default_method
        self._check_maps(method, float(m.exponent))
        defines, terms = self._variant(m)
        scale = np.abs(np.linalg.eigvalsh(obj.model[:3, :3].T @ obj.model[:3, :3])).max() ** 0.5
        program, vaos, sphere = self._geometry(obj, defines, scale)
        errors = np.array([0.0] + [error * scale for _, error in obj.lods])[:len(vaos)]
        textures = {"light_map": self._image_texture(m.light_map) if m.light_map is not None else None,
                    "normal_map": self._image_texture(m.normal_map) if m.normal_map is not None else None,
                    "coefficient_map": self._coefficient_texture(m.directional_map) if m.directional_map is not None else None}
        prt_target = None
        if m.prt_variant:
            prt_target, prt_textures = self._prt_targets(obj)
            textures.update(prt_textures)
        if m.model == "ggx":
            textures.update(self._ggx_textures(m))
        if terms:
            program["inm_terms"].value = terms
        # What does not change from frame to frame, set once: each object has its own program.
        if m.model == "ggx":
            base, metallic = np.asarray(m.base_color, dtype=np.float64), float(m.metallic)
            program["kd"].value = tuple((1.0 - metallic) * base)
            program["f0"].value = tuple(0.04 * (1.0 - metallic) + base * metallic)  # GLSL's mix(0.04, base, metallic)
            program["roughness"].value = float(m.roughness)
            program["ggx_levels"].value = float(len(m.ggx_chain))
        else:
            program["kd"].value, program["ks"].value = tuple(m.kd), tuple(m.ks)
        units = self._bind_units(program, method, m, textures)
        texel_world = {name: scale * texel_length(obj.mesh, obj.mesh.uvs if name == "normal_map" else obj.mesh.uvs2,
                                                  max(tex.size[:2])) for name, tex in textures.items()
                       if tex is not None and name not in ("sep_basis", "ggx_map", "brdf_lut")}  # (tables over directions: no mip level)
        corners = np.hstack([obj.corners(), np.ones((8, 1))])
        prt = (m, prt_target) if m.prt_variant else None
        self.objects.append(_Drawable(program, vaos, errors, units, corners, texel_world, sphere, obj.orbit, obj.model.copy(), prt))
        if prt is not None and m.prt_light is not None:
            self._relight(self.objects[-1], m.prt_light)
        self.corners = np.stack([d.corners for d in self.objects])

    def _ggx_textures(self, m: Material) -> dict:
        """A GGX material's prefiltered cube map (one texture per chain, shared by the objects lit by it) and
        the split sum's table (one per renderer)."""
        from arsim.lighting.ggx import brdf_lut

        chain = m.ggx_chain
        if chain is None or len(chain) < 2 or any(np.shape(a) != (6, chain[0].shape[1] >> p, chain[0].shape[1] >> p, 3)
                                                   for p, a in enumerate(chain)):
            raise ArsimError("a ggx material needs its prefiltered cube map, levels (6, N >> p, N >> p, 3); "
                             "light the objects with content.light_objects")
        cache = self._ggx_cache
        if id(chain) not in cache:
            cache[id(chain)] = (chain, self._cube_chain_texture(chain))  # (the chain kept: its id stays its own)
        if "lut" not in cache:
            lut = np.ascontiguousarray(brdf_lut().astype(np.float32))  # row 0: roughness near 0 (GL's t = 0)
            texture = self.ctx.texture(lut.shape[:2][::-1], 2, lut.tobytes(), dtype="f4")
            texture.repeat_x = texture.repeat_y = False
            cache["lut"] = texture
        return {"ggx_map": cache[id(chain)][1], "brdf_lut": cache["lut"]}

    def _cube_chain_texture(self, chain: list):
        """A float RGBA cube map texture whose mip levels are the chain's (OpenGL's face order and orientation,
        core.conventions.CUBE_FACES): level 0 uploaded, the chain's levels written over the generated ones by a
        compute shader (moderngl writes a cube map's faces at level 0 only)."""
        def rgba(level):
            return np.ascontiguousarray(np.concatenate([level, np.ones(level.shape[:3] + (1,))], axis=-1).astype(np.float32))

        size = chain[0].shape[1]
        texture = self.ctx.texture_cube((size, size), 4, rgba(chain[0]).tobytes(), dtype="f4")
        texture.build_mipmaps(0, len(chain) - 1)
        texture.filter = self.ctx.LINEAR_MIPMAP_LINEAR, self.ctx.LINEAR
        if self._cube_writer is None:
            self._cube_writer = self.ctx.compute_shader(_shader("cube_level.comp"))
        for p in range(1, len(chain)):
            n = size >> p
            buffer = self.ctx.buffer(rgba(chain[p]).tobytes())
            buffer.bind_to_storage_buffer(0)
            texture.bind_to_image(0, read=False, write=True, level=p)
            self._cube_writer["size"].value = n
            self._cube_writer.run((n + 7) // 8, (n + 7) // 8, 6)
            self.ctx.memory_barrier()
            buffer.release()
        return texture

    def _check_maps(self, method: str, exponent: float) -> None:
        """ArsimError naming what is held where the method has no irradiance map or none for the exponent."""
        missing = [s for s in (1.0, exponent) if (method, s) not in self.maps]
        if missing:
            held = ", ".join(sorted({f"{name or 'default'}: " + ", ".join(f"{s:g}" for n, s in sorted(self.maps) if n == name)
                                     for name, _ in self.maps}))
            raise ArsimError(f"no {method or 'default'} maps for exponent {', '.join(f'{s:g}' for s in missing)} "
                             f"(the maps held: {held}); compute or load that method's maps for every exponent the objects use")

    def _variant(self, m: Material) -> tuple[list[str], int]:
        """The shader variant's defines for a material (its maps checked), and its directional light map's
        terms (0: none)."""
        defines = (["LIGHT_MAP"] if m.light_map is not None else []) + (["NORMAL_MAP"] if m.normal_map is not None else [])
        terms = 0
        if m.directional_map is not None:
            basis, count = parse_basis(m.basis)
            if m.directional_map.ndim != 4 or m.directional_map.shape[2:] != (count, 3):
                raise ArsimError(f"a {m.basis} directional light map holds (H, W, {count}, 3) coefficients, "
                                 f"not {m.directional_map.shape}; bake it for that basis")
            terms = count if m.inm_terms is None else m.inm_terms
            if not 1 <= terms <= count:
                raise ArsimError(f"inm_terms {terms}: the {m.basis} light map has 1 to {count} terms")
            defines += ["INM", f"BASIS_{basis.name.upper()}", f"BASIS_COUNT {count}"]
        if m.prt_variant:
            if m.directional_map is not None:
                raise ArsimError("a material takes a directional light map or a PRT transfer, not both")
            defines, terms = self._prt_variant(m, defines)
        if m.irradiance_volume is not None:
            if m.directional_map is not None:
                raise ArsimError("a material takes a directional light map or an irradiance volume, not both")
            volume = np.asarray(m.irradiance_volume[0])
            if volume.ndim != 5 or volume.shape[3:] != (9, 3) or min(volume.shape[:3]) < 2:
                raise ArsimError(f"an irradiance volume holds (X, Y, Z, 9, 3) coefficients on at least 2 points per axis, "
                                 f"not {volume.shape}")
            defines.append("VOLUME")
        defines += ["GGX"] if m.model == "ggx" else []
        defines += ["DEBUG"] if self.debug else []
        defines += ["FLOAT_FILTERING"] if "llvmpipe" in self.ctx.info["GL_RENDERER"] else []
        return defines, terms

    def _prt_variant(self, m: Material, defines: list[str]) -> tuple[list[str], int]:
        """A PRT material's defines (its matrices checked) and its count of coefficients."""
        from arsim.lighting.prt import get_variant

        variant = get_variant(m.prt_variant)
        shape = m.prt_compressed.means.shape[1:2] if m.prt_compressed is not None else None
        matrices = m.prt_matrices
        if matrices is None or matrices.ndim not in (3, 4) or matrices.shape[-2] != variant.count:
            raise ArsimError(f"a prt-{variant.name} material holds (V, {variant.count}, L2) or (H, W, {variant.count}, L2) "
                             f"matrices, not {None if matrices is None else matrices.shape}; compute its transfer for that variant")
        if shape is not None and shape != (variant.count,):
            raise ArsimError(f"the compressed prt-{variant.name} transfer has {shape[0]} coefficients, not {variant.count}")
        basis = {"gs": "SH", "hl2": "HL2", "sal": "HSH"}.get(variant.name, "SEP")
        defines = defines + ["INM", "PRT", f"BASIS_{basis}", f"BASIS_COUNT {variant.count}"]
        if matrices.ndim == 3 and m.prt_compressed is not None:  # CPCA summed per vertex on the GPU
            defines += ["PRT_CPCA", f"PRT_VECTORS {m.prt_compressed.vectors.shape[1]}"]
        return defines + (["PRT_VERTEX"] if matrices.ndim == 3 else []), variant.count

    def _prt_targets(self, obj: SceneObject) -> tuple[object, dict]:
        """Where a PRT object's coefficients go (a storage buffer per vertex, or a texture array per texel,
        zeros until relit) and the textures its program reads (the separable basis's)."""
        from arsim.lighting.prt import get_variant

        m = obj.material
        variant = get_variant(m.prt_variant)
        textures = {}
        if variant.separable is not None:
            table = np.ascontiguousarray(np.pad(variant.separable.texture, ((0, 0), (0, 0), (0, 4 - variant.count))))
            sep = self.ctx.texture(table.shape[:2][::-1], 4, table.astype(np.float32).tobytes(), dtype="f4")
            sep.filter = self.ctx.NEAREST, self.ctx.NEAREST  # (bilinear in the shader, in float, as the reference)
            textures["sep_basis"] = sep
        if m.prt_matrices.ndim == 3:
            if len(m.prt_matrices) != len(obj.mesh.positions):
                raise ArsimError(f"the PRT transfer has {len(m.prt_matrices)} vertices, the mesh {len(obj.mesh.positions)}; "
                                 f"compute it for this mesh")
            c = m.prt_compressed
            if c is not None:  # per vertex its cluster and weights, static; per frame the clusters' coefficients
                static = np.hstack([c.labels[:, None].astype(np.float32), c.weights.astype(np.float32)])
                table = self.ctx.buffer(reserve=c.means.shape[0] * (1 + c.vectors.shape[1]) * variant.count * 3 * 4)
                return (table, self.ctx.buffer(np.ascontiguousarray(static).tobytes())), textures
            return self.ctx.buffer(reserve=len(m.prt_matrices) * variant.count * 3 * 4), textures
        h, w = m.prt_matrices.shape[:2]
        texture = self._coefficient_texture(np.zeros((h, w, variant.count, 3), np.float32))
        textures["coefficient_map"] = texture
        return texture, textures

    def relight(self, light: np.ndarray) -> None:
        """Set every PRT object's coefficients from the light's SH (order^2, 3), world axes
        (lighting.prt.light_sh): per point, its matrices times the light (the relighting of every frame
        where the light changes)."""
        for d in self.objects:
            if d.prt is not None:
                self._relight(d, light)

    def relight_probe(self, anglemap: np.ndarray) -> None:
        """Relight every PRT object from an angle-map light: its SH to each object's order, then relight."""
        from arsim.lighting.prt import light_sh

        lights = {}
        for d in self.objects:
            if d.prt is not None:
                m = d.prt[0]
                order = int(round(np.sqrt((m.prt_compressed.means if m.prt_compressed is not None else m.prt_matrices).shape[-1])))
                if order not in lights:
                    lights[order] = light_sh(anglemap, order)
                self._relight(d, lights[order])

    def _relight(self, d: _Drawable, light: np.ndarray) -> None:
        from arsim.lighting.prt import relight

        m, target = d.prt
        order2 = (m.prt_compressed.means if m.prt_compressed is not None else m.prt_matrices).shape[-1]
        if np.shape(light) != (order2, 3):
            raise ArsimError(f"the light has {np.shape(light)} SH coefficients; this PRT object needs ({order2}, 3)")
        if m.prt_matrices.ndim == 3 and m.prt_compressed is not None:
            target[0].write(np.ascontiguousarray(m.prt_compressed.cluster_coefficients(light)).tobytes())
            return
        coefficients = (m.prt_compressed.relight(light) if m.prt_compressed is not None
                        else relight(m.prt_matrices.reshape(-1, *m.prt_matrices.shape[-2:]), light))
        if m.prt_matrices.ndim == 3:
            target.write(np.ascontiguousarray(coefficients, dtype=np.float32).tobytes())
        else:
            h, w = m.prt_matrices.shape[:2]
            grid = coefficients.reshape(h, w, -1, 3)[::-1]
            target.write(np.ascontiguousarray(np.moveaxis(grid, 2, 0), dtype=np.float32).tobytes())
            target.build_mipmaps()

    def _geometry(self, obj: SceneObject, defines: list[str], scale: float):
        """The object's program and vertex arrays (one per level of detail): a ray-cast sphere's quad where
        it is a plain sphere, else its meshes; and the sphere (centre, radius) or None."""
        m = obj.material
        if (obj.sphere is not None and m.light_map is None and m.normal_map is None and m.directional_map is None
                and not m.prt_variant):
            # (an irradiance volume is read at the ray-cast hit: the impostor serves it too)
            defines = defines + ["SPHERE_IMPOSTOR"]
            program = self.ctx.program(vertex_shader=_source("sphere.vert", defines), fragment_shader=_source("object.frag", defines))
            quad = np.array([(-1, -1), (1, -1), (-1, 1), (-1, 1), (1, -1), (1, 1)], dtype="f4")  # counter-clockwise
            vaos = [self.ctx.vertex_array(program, [(self.ctx.buffer(quad.tobytes()), "2f", "in_corner")])]
            sphere = (obj.model[:3, 3].astype(np.float64), float(obj.sphere * scale))
            program["center"].value, program["radius"].value = tuple(sphere[0]), sphere[1]
            return program, vaos, sphere
        if obj.torus is not None and m.directional_map is None and not m.prt_variant:
            defines = defines + ["TORUS_IMPOSTOR"]  # (its light and normal maps read at the ray-cast hit's UVs)
            meshes = (obj.torus[2],)
        else:  # (per-vertex PRT coefficients are indexed by the mesh's vertices: no coarser meshes)
            meshes = (obj.mesh, *(mesh for mesh, _ in obj.lods)) if "PRT_VERTEX" not in defines else (obj.mesh,)
        program = self.ctx.program(vertex_shader=_source("object.vert", defines), fragment_shader=_source("object.frag", defines))
        sizes = {"in_position": 3, "in_normal": 3, "in_tangent": 3, "in_uv": 2, "in_uv2": 2}
        used = [n for n in sizes if n in program]  # the compiler drops what a variant does not read
        layout = " ".join(f"{k}f" if n in used else f"{k}x4" for n, k in sizes.items())
        vaos = [self.ctx.vertex_array(program, [(self.ctx.buffer(mesh.interleaved().tobytes()), layout, *used)],
                                      self.ctx.buffer(mesh.indices.astype(np.uint32).tobytes())) for mesh in meshes]
        if "TORUS_IMPOSTOR" in defines:
            program["torus_radii"].value = obj.torus[:2]
        _place(program, obj.model)
        return program, vaos, None

    def _bind_units(self, program, method: str, m: Material, textures: dict) -> list:
        """The textures the object's draws bind, in unit order (the method's maps, the material's own, its
        irradiance volume's), each sampler of the program set to its unit."""
        units = [self.maps[method, 1.0], self.maps[method, float(m.exponent)]] + [t for t in textures.values() if t is not None]
        names = ["irradiance_map", "reflection_map"] + [n for n, t in textures.items() if t is not None]
        for unit, name in enumerate(names):
            if name in program:  # (a directional light map replaces the irradiance map: the compiler drops it)
                program[name].value = unit
        if m.irradiance_volume is not None:
            volume, low, high = m.irradiance_volume
            volume_textures = self._volume_textures(np.asarray(volume))
            program["volume_low"].value, program["volume_high"].value = tuple(map(float, low)), tuple(map(float, high))
            program["volume_size"].value = tuple(float(n) for n in np.asarray(volume).shape[:3])
            program["volume"].value = list(range(len(units), len(units) + len(volume_textures)))
            units += volume_textures
        return units

    def _move(self, time_s: float) -> None:
        """The objects that move, placed where their orbits have them at time_s (model matrix, a sphere's
        centre, the bounding box's corners)."""
        for k, d in enumerate(self.objects):
            if d.orbit is None:
                continue
            offset = d.orbit.offset(time_s)
            model = d.model.copy()
            model[:3, 3] += offset
            if d.sphere is not None:
                d.sphere = (model[:3, 3].astype(np.float64), d.sphere[1])
                d.program["center"].value = tuple(d.sphere[0])
            else:
                _place(d.program, model)
            self.corners[k, :, :3] = d.corners[:, :3] + offset

    def screen_rects(self, view_projection: np.ndarray) -> list[tuple[int, int, int, int]]:
        """Per object that can be in view, the frame's rectangle (x, y from the bottom, w, h) that holds
        it: its bounding box projected, a pixel around; the whole frame when the box reaches behind the
        near plane."""
        width, height = self.camera.width, self.camera.height
        clip = self.corners @ view_projection.T  # (objects, 8, 4)
        w = clip[..., 3]
        pixels = (clip[..., :2] / np.where(w > 0, w, 1.0)[..., None] * 0.5 + 0.5) * [width, height]
        low = np.maximum(np.floor(pixels.min(axis=1)).astype(int) - 1, 0)
        high = np.minimum(np.ceil(pixels.max(axis=1)).astype(int) + 1, [width, height])
        rects = []
        for k in range(len(clip)):
            if (w[k] < self.near).any():
                if (w[k] > 0).any():
                    rects.append((0, 0, width, height))
            elif (high[k] > low[k]).all():
                rects.append((int(low[k, 0]), int(low[k, 1]), int(high[k, 0] - low[k, 0]), int(high[k, 1] - low[k, 1])))
        return rects

    def _tile(self, width: int, height: int) -> _Tile:
        size = (min(_power_of_two(width), _power_of_two(self.camera.width)),
                min(_power_of_two(height), _power_of_two(self.camera.height)))
        if size not in self.tiles:
            hdr = self.ctx.texture(size, 4, dtype="f2")
            debug = [self.ctx.texture(size, 4, dtype="f4") for _ in range(2)] if self.debug else []
            depth = self.ctx.depth_renderbuffer(size)
            fbo = self.ctx.framebuffer([hdr, *debug], depth)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)  # (a new texture's content is undefined)
            average = self.ctx.texture((size[0] // AVERAGE_BLOCK, size[1] // AVERAGE_BLOCK), 2, dtype="f4")
            self.tiles[size] = _Tile(hdr, fbo, self.ctx.framebuffer(debug, depth), bytes(size[0] * size[1] * 8),
                                     average, self.ctx.framebuffer([average]), debug)
        return self.tiles[size]

    def no_objects(self) -> None:
        """A frame without objects (the tag lost): the tone mapping leaves the camera frame as it is."""
        self.rect = self.tile = None
        self.rects = []

    def render_objects(self, rotation: Rotation, translation: np.ndarray, time_s: float = 0.0) -> None:
        """Step 5: the objects into the HDR colour and the mask, seen from the OpenCV world-to-camera
        pose (x_cam = R x_world + t), those that move where they are at time_s."""
        self._move(time_s)
        view = gl_view_from_opencv_pose(rotation, translation)
        view_projection = self.projection @ view
        eye = -rotation.as_matrix().T @ np.asarray(translation, dtype=np.float64)
        self.rects = merge_rects(self.screen_rects(view_projection))
        if not self.rects:
            return self.no_objects()
        corners = np.array([(x, y, x + w, y + h) for x, y, w, h in self.rects])
        x0, y0 = corners[:, :2].min(axis=0)
        x1, y1 = corners[:, 2:].max(axis=0)
        self.rect = (int(x0), int(y0), int(x1 - x0), int(y1 - y0))
        x, y, w, h = self.rect
        self.tile = self._tile(w, h)
        self.tile.fbo.use()
        self.tile.clear([(rx - x, ry - y, rw, rh) for rx, ry, rw, rh in self.rects])
        self.tile.fbo.viewport = (-x, -y, self.camera.width, self.camera.height)  # the rectangle's corner at the tile's
        self.ctx.enable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)  # closed meshes: their back faces are hidden
        depths = np.maximum((self.corners @ view_projection.T)[..., 3].min(axis=1), self.near)  # nearest points
        for d, depth in zip(self.objects, depths):
            program = d.program
            program["view_projection"].write(view_projection.T.astype("f4").tobytes())
            program["eye"].value = tuple(eye)
            for unit, tex in enumerate(d.units):
                tex.use(unit)
            if d.prt is not None and d.prt[0].prt_matrices.ndim == 3:
                for binding, buffer in enumerate(d.prt[1] if isinstance(d.prt[1], tuple) else (d.prt[1],)):
                    buffer.bind_to_storage_buffer(binding)
            # The light and normal maps' mip level per object and frame, log2 of texels per pixel where it is
            # nearest: llvmpipe's per-pixel level (derivatives, two levels) took 40 % of the torus's time.
            for name, length in d.texel_world.items():
                program[f"{name}_lod"].value = max(float(np.log2(depth / (length * self.camera.fx))), 0.0) if length > 0 else 0.0
            # (math.dist: numpy's norm of three numbers went through BLAS and let go of the GIL, and in the session
            # each call then waited on the threads beside the loop: 0.9 s of its main thread a run)
            if d.sphere is not None and math.dist(d.sphere[0], eye) <= d.sphere[1] * 1.001:
                continue  # the camera inside a sphere: its back faces, culled
            on_screen = d.errors * self.camera.fx / depth
            d.vaos[max(k for k, px in enumerate(on_screen) if px <= LOD_ERROR_PX or k == 0)].render()
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.CULL_FACE)

    def _tonemapper(self, log_average: bool):
        """The average's program and the tone mapper's, for the mean or the log-average."""
        if log_average not in self.tonemappers:
            defines = ["LOG_AVERAGE"] if log_average else []
            average = self.ctx.program(vertex_shader=_source("blocks.vert", []),
                                       fragment_shader=_source("average.frag", defines + [f"BLOCK {AVERAGE_BLOCK}"]))
            program = self.ctx.program(vertex_shader=_source("rects.vert", defines + ["AVERAGE"]),
                                       fragment_shader=_source("tonemap.frag", defines))
            self.tonemappers[log_average] = (average, program)
        return self.tonemappers[log_average]

    def _draw_rects(self, program, rects: np.ndarray) -> None:
        """Two triangles per rectangle (x0, y0, x1, y1) with the program, into the framebuffer in use. The
        corners go into a buffer kept per program (grown when a frame has more rectangles), not one made
        and released per draw."""
        corners = np.array([[(x0, y0), (x1, y0), (x0, y1), (x0, y1), (x1, y0), (x1, y1)] for x0, y0, x1, y1 in rects], dtype="f4")
        vbo, vao = self._rect_arrays.get(id(program), (None, None))
        if vbo is None or vbo.size < corners.nbytes:
            if vbo is not None:
                vao.release()
                vbo.release()
            vbo = self.ctx.buffer(reserve=max(corners.nbytes, 64 * 48))
            vao = self.ctx.vertex_array(program, [(vbo, "2f", "in_corner")])
            self._rect_arrays[id(program)] = (vbo, vao)
        vbo.write(corners.tobytes())
        vao.render(vertices=6 * len(rects))

    def _average_pass(self, program) -> None:
        """The blocks that hold the objects' rectangles summed into the tile's average target (zeros
        elsewhere), and the blocks' box kept: what the tone mapper sums (average_sum.glsl)."""
        tile, b = self.tile, AVERAGE_BLOCK
        # (zeros uploaded: llvmpipe's clear of the target took ten times as long in the frame)
        tile.average.write(memoryview(tile.zeros)[:tile.average.width * tile.average.height * 8])
        tile.average_fbo.use()
        x0, y0 = self.rect[:2]
        rects = np.array([(x - x0, y - y0, x - x0 + w, y - y0 + h) for x, y, w, h in self.rects])
        blocks = np.hstack([rects[:, :2] // b, -(-rects[:, 2:] // b)])  # grown to whole blocks
        tile.hdr.use(0)
        program["hdr"].value = 0
        program["target_size"].value = tile.average.size
        self._draw_rects(program, blocks)
        width, height = tile.average.size
        tile.box = (max(int(blocks[:, 0].min()), 0), max(int(blocks[:, 1].min()), 0),
                    min(int(blocks[:, 2].max()), width), min(int(blocks[:, 3].max()), height))

    def tonemap(self, background: np.ndarray, key: float = 0.18, white: float = 2.0, log_average: bool = False) -> np.ndarray:
        """Steps 4 and 6: the camera frame (H, W, 3) uint8 with Reinhard's operator on the masked pixels
        over it, with the masked pixels' mean luminance or (log_average) their log-average; the 8-bit
        result (H, W, 3), row 0 at the top."""
        self.background_pass(background)
        self.tonemap_pass(key, white, log_average)
        return self.read_output()

    def background_pass(self, background: np.ndarray) -> None:
        """Step 4: the camera frame (H, W, 3) RGB or (H, W, 4) RGBA uint8, row 0 at the top, into the output.
        RGBA is uploaded as it is (the session decodes its frames so: core.png.read_frame's alpha); RGB is
        converted first, which took a third of step 4's time on llvmpipe (README: Rendering speed)."""
        if background.shape[-1] == 4:
            self.output.write(np.ascontiguousarray(background))
        else:
            self.output.write(cv2.cvtColor(background, cv2.COLOR_RGB2RGBA, dst=self._rgba))

    def tonemap_pass(self, key: float = 0.18, white: float = 2.0, log_average: bool = False) -> None:
        """Step 6: the tone-mapped objects over the output's background, without reading it back."""
        if self.tile is None:
            return
        average, program = self._tonemapper(log_average)
        self._average_pass(average)
        for unit, (name, tex) in enumerate([("hdr", self.tile.hdr), ("blocks", self.tile.average)]):
            tex.use(unit)
            program[name].value = unit
        program["box"].value = self.tile.box
        program["key"].value, program["white"].value = key, white
        program["origin"].value = self.rect[:2]
        program["frame_size"].value = (self.camera.width, self.camera.height)
        program["frame_height"].value = self.camera.height
        # Only the objects' own rectangles (two triangles each; where they overlap, a pixel is mapped twice
        # to the same value): a fraction of their union, which holds the space between them.
        self.output_fbo.use()
        self._draw_rects(program, np.array([(x, y, x + w, y + h) for x, y, w, h in self.rects]))

    def overlay_pass(self, lines: Sequence[str], thumbnail=None) -> None:
        """Step 7: the user interface, lines of text (frame time, bake progress) in a translucent box at
        the frame's top left, blended over the output; below it, optionally, a thumbnail of an HDR
        angle-map texture (the map being baked: the thesis's progress display, black where no tile is
        done yet), its rows bottom-up (t upwards)."""
        coverage = overlay_coverage(lines, self.camera.height)  # (a quarter of the RGBA image's bytes to upload)
        h, w = coverage.shape[:2]
        if self.overlay_program is None:
            programs = {}
            for name, defines in (("text", [f"BOX_ALPHA {OVERLAY_BOX_ALPHA}"]), ("thumbnail", ["THUMBNAIL"])):
                program = self.ctx.program(vertex_shader=_source("fullscreen.vert", []), fragment_shader=_source("overlay.frag", defines))
                programs[name] = (program, self.ctx.vertex_array(program, []))
            self.overlay_program = (programs, {})
        programs, textures = self.overlay_program
        if (w, h) not in textures:
            textures[(w, h)] = self.ctx.texture((w, h), 1, dtype="f1")
            textures[(w, h)].filter = self.ctx.NEAREST, self.ctx.NEAREST
        texture = textures[(w, h)]
        texture.write(coverage)  # (the output's rows run from the top: no flip)
        margin = max(self.camera.height // 90, 2)
        self.overlay_box = np.s_[margin:margin + h, margin:margin + w]  # in the image, row 0 at the top
        self.output_fbo.use()
        self.ctx.enable(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        program, vao = programs["text"]
        texture.use(0)
        program["image"].value = 0
        self.output_fbo.viewport = (margin, margin, w, h)
        vao.render(vertices=3)
        self.ctx.disable(self.ctx.BLEND)
        if thumbnail is not None:
            side = min(self.camera.height // 4, self.camera.width // 4)
            program, vao = programs["thumbnail"]
            thumbnail.use(0)
            program["image"].value = 0
            self.output_fbo.viewport = (margin, 2 * margin + h, side, side)
            vao.render(vertices=3)
            self.overlay_box = np.s_[margin:2 * margin + h + side, margin:margin + max(w, side)]
        self.output_fbo.viewport = (0, 0, self.camera.width, self.camera.height)

    def update_map(self, method: str, exponent: float, anglemap: np.ndarray) -> None:
        """Replace a map in place (the objects that read it see the new one from the next frame): how the
        baked maps take over from the ones used while they were baked. Same size as the one it replaces."""
        data = _with_alpha(extend_beyond_rim(anglemap), np.float32)
        self.maps[method or self.default_method, float(exponent)].write(data.tobytes())

    def _read(self, texture, components: int, dtype: str, level: int = 0) -> np.ndarray:
        """A tile texture's level as an image; level 0 placed into the frame (zeros around the objects'
        rectangle), row 0 at the top."""
        w, h = max(texture.width >> level, 1), max(texture.height >> level, 1)
        np_dtype = {"f2": np.float16, "f4": np.float32}[dtype]
        data = np.frombuffer(texture.read(level=level), dtype=np_dtype).reshape(h, w, components).astype(np.float32)
        if level == 0:
            x, y, rw, rh = self.rect
            frame = np.zeros((self.camera.height, self.camera.width, components), np.float32)
            frame[y:y + rh, x:x + rw] = data[:rh, :rw]
            data = frame
        return data[::-1]

    def _read_tile(self, name: str, components: int, dtype: str) -> np.ndarray:
        if self.tile is None:  # nothing in view: nothing drawn
            return np.zeros((self.camera.height, self.camera.width, components), np.float32)
        return self._read(getattr(self.tile, name), components, dtype)

    def read_output(self) -> np.ndarray:
        """The frame (H, W, 3) uint8 after the last passes."""
        data = np.frombuffer(self.output.read(), dtype=np.uint8).reshape(self.camera.height, self.camera.width, 4)
        # (contiguous: a copy of the RGB view, as numpy or OpenCV's bindings make it, took 4-7 ms a 1280 x 720 frame)
        return cv2.cvtColor(data, cv2.COLOR_RGBA2RGB)

    def read_hdr(self) -> np.ndarray:
        return self._read_tile("hdr", 4, "f2")[..., :3]

    def read_mask(self) -> np.ndarray:
        """(H, W) 1 where an object was drawn, 0 elsewhere: the HDR colour's alpha (read every frame: only the
        alpha is converted and placed into the frame)."""
        frame = np.zeros((self.camera.height, self.camera.width), np.float32)
        if self.tile is not None:
            texture, (x, y, w, h) = self.tile.hdr, self.rect
            alpha = np.frombuffer(texture.read(), dtype=np.float16).reshape(texture.height, texture.width, 4)[:h, :w, 3]
            frame[y:y + h, x:x + w] = alpha
        return frame[::-1]

    def read_debug(self) -> tuple[np.ndarray, np.ndarray]:
        """(normal (H, W, 4): the shaded normal and the light-map value in w, incident (H, W, 4))."""
        return tuple(self._read(t, 4, "f4") for t in self.tile.debug)

    def mip_average(self, log_average: bool = False) -> float:
        """The average luminance of the masked pixels as the tone mapper sums it (after a tonemap pass with
        the same log_average): the same sums of the same blocks (average_sum.glsl), drawn into a 1 x 1 target
        and read back."""
        if self._sum_program is None:
            program = self.ctx.program(vertex_shader=_source("blocks.vert", []), fragment_shader=_source("average_sum.frag", []))
            total = self.ctx.texture((1, 1), 2, dtype="f4")
            self._sum_program = (program, total, self.ctx.framebuffer([total]))
        program, total, fbo = self._sum_program
        fbo.use()
        self.tile.average.use(0)
        program["blocks"].value = 0
        program["box"].value = self.tile.box
        program["target_size"].value = (1, 1)
        self._draw_rects(program, np.array([(0, 0, 1, 1)]))
        value, coverage = np.frombuffer(total.read(), np.float32)
        mean = value / max(coverage, 1e-12)
        return float(np.exp(mean) if log_average else mean)
