"""Render speed at 1280 x 720 along the default scenario's AR path (prints figures; not a test): thesis
5.1 steps 4-7 per frame, the camera frame as the background (4), the virtual objects into the HDR colour
and the mask with IBL, light maps and normal maps (5), the masked tone mapping with its average (6) and
the overlay (7), each timed on the CPU around glFinish and with GL timer queries; median, p95 and max
over the frames where the tag is in view (the look-away windows, which draw nothing, are left out).

Beside it, the floor: the same frames, at the same resolution, in the same context and interleaved frame
by frame with the renderer's, drawn as cheaply as the steps can be drawn at all, and the ratio of the
two medians per step:
  4  the camera frame uploaded as RGBA already (no conversion; the renderer's step 4 is the same upload now, as
     the session decodes its frames to RGBA, so its ratio is 1 but for noise);
  5  the same tile, clear and depth test, each object's coarsest geometry (a ray-cast sphere's quad, a
     mesh's coarsest level of detail) with a shader that writes a constant colour (its alpha the mask);
  6  one pass over the same rectangles that copies the HDR colour where it is set (no average, no
     operator);
  7  the same box blended from the text's coverage already uploaded (no text drawn).

And the least shading the thesis allows: the renderer's own steps 4, 6 and 7, with step 5 drawn on the floor's
geometry by a shader that does only what Alg. 5.1 asks of every pixel, its two angle-map lookups (the
irradiance map at the normal, the reflection map in the mirror direction) and kd, ks: no ray-cast surface, no
normal or light map (a sphere's quad cut to its outline, the normal of the quad's point about the centre; a
mesh's interpolated normal). What the renderer
spends above it is what its exact surfaces and its light and normal maps cost.

    python benchmarks/bench_render.py [--frames N] [--width W --height H] [--log-average] [--scenario NAME]

--scenario: another scenario's objects (lit from its environment as a session lights them: directional light
maps, PRT, GGX) along its AR path, instead of the default scenario's; a bundled name or a TOML file.
"""

import argparse
import time

import numpy as np

from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import core_shader, create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.fast import fast_maps
from arsim.lighting.mapset import MapSet
from arsim.render.content import light_objects, scene_objects
from arsim.render.renderer import OVERLAY_BOX_ALPHA, Renderer, _source, overlay_coverage
from arsim.scenario.environment import load_environment
from arsim.scenario.loader import load_scenario
from arsim.sensors.recording import ar_path

FLOOR_VERT = """#version 430
uniform mat4 model;
uniform mat4 view_projection;
in vec3 in_position;
void main() { gl_Position = view_projection * (model * vec4(in_position, 1.0)); }
"""
FLOOR_FRAG = """#version 430
uniform vec3 eye;  // (set by render_objects: kept by a branch the compiler cannot drop)
layout(location = 0) out vec4 hdr;
void main() {
    hdr = vec4(0.5, 0.5, 0.5, 1.0);
    if (eye.x > 1e30) hdr.r = 0.0;
}
"""
COPY_FRAG = """#version 430
uniform sampler2D hdr;
uniform ivec2 origin;
uniform int frame_height;
out vec4 colour;
void main() {
    vec4 pixel = texelFetch(hdr, ivec2(int(gl_FragCoord.x), frame_height - 1 - int(gl_FragCoord.y)) - origin, 0);
    if (pixel.a < 0.5) discard;
    colour = vec4(pixel.rgb, 1.0);
}
"""
LEAST_VERT = """#version 430
uniform mat4 model;
uniform mat4 view_projection;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_world;
out vec3 v_normal;
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    v_world = world.xyz;
    v_normal = mat3(model) * in_normal;
    gl_Position = view_projection * world;
}
"""
LEAST_FRAG = """
uniform sampler2D irradiance_map;
uniform sampler2D reflection_map;
uniform vec3 kd;
uniform vec3 ks;
uniform vec3 eye;
#ifdef SPHERE
uniform vec3 center;
uniform float radius;
#else
in vec3 v_normal;
#endif
in vec3 v_world;
layout(location = 0) out vec4 hdr;
vec3 lookup(sampler2D map, vec3 d) {
    vec2 st = anglemap_st(d);
    return texture(map, vec2(st.x, 1.0 - st.y)).rgb;
}
void main() {
    vec3 v = normalize(v_world - eye);
#ifdef SPHERE
    vec3 oc = eye - center;  // (the quad's corners, outside the outline, are not the sphere's)
    float b = dot(v, oc);
    if (b * b < dot(oc, oc) - radius * radius) discard;
    vec3 n = normalize(v_world - center);
#else
    vec3 n = normalize(v_normal);
#endif
    hdr = vec4(kd * lookup(irradiance_map, n) + ks * lookup(reflection_map, reflect(v, n)), 1.0);
}
"""
QUAD = np.array([(-1, -1), (1, -1), (-1, 1), (-1, 1), (1, -1), (1, 1)], dtype="f4")  # an impostor's, counter-clockwise


def coarsest_geometry(ctx, d, obj, vertex: str, fragment: str, sphere_fragment: str, normals: bool = False):
    """The object's cheapest geometry with the given shaders, (program, vertex array): a ray-cast sphere's quad
    (sphere.vert, sphere_fragment), else its coarsest mesh (vertex, fragment; positions, and normals where asked)."""
    if d.sphere is not None:
        program = ctx.program(vertex_shader=_source("sphere.vert", []), fragment_shader=sphere_fragment)
        program["center"].value, program["radius"].value = tuple(d.sphere[0]), d.sphere[1]
        return program, ctx.vertex_array(program, [(ctx.buffer(QUAD.tobytes()), "2f", "in_corner")])
    program = ctx.program(vertex_shader=vertex, fragment_shader=fragment)
    program["model"].write(obj.model.T.astype("f4").tobytes())
    mesh = obj.lods[-1][0] if obj.lods else obj.mesh
    names = ("in_position", "in_normal") if normals else ("in_position",)
    data = np.hstack([mesh.positions, mesh.normals] if normals else [mesh.positions]).astype("f4")
    return program, ctx.vertex_array(program, [(ctx.buffer(data.tobytes()), " ".join(["3f"] * len(names)), *names)],
                                     ctx.buffer(mesh.indices.astype(np.uint32).tobytes()))


class LeastRenderer(Renderer):
    """The renderer with step 5 at the least shading the thesis allows (module docstring): the floor's geometry,
    two angle-map lookups a pixel."""

    def add(self, obj) -> None:
        super().add(obj)
        d = self.objects[-1]
        header = "#version 430\n" + core_shader("anglemap.glsl")
        program, vao = coarsest_geometry(self.ctx, d, obj, LEAST_VERT, header + LEAST_FRAG,
                                         header.replace("\n", "\n#define SPHERE\n", 1) + LEAST_FRAG, normals=True)
        program["irradiance_map"].value, program["reflection_map"].value = 0, 1
        program["kd"].value, program["ks"].value = tuple(obj.material.kd), tuple(obj.material.ks)
        d.program, d.vaos, d.errors, d.units, d.texel_world = program, [vao], np.zeros(1), d.units[:2], {}


class FloorRenderer(Renderer):
    """The renderer's tiles, rectangles and passes with the cheapest work in each (module docstring)."""

    def add(self, obj) -> None:
        super().add(obj)
        d = self.objects[-1]
        program, vao = coarsest_geometry(self.ctx, d, obj, FLOOR_VERT, FLOOR_FRAG, FLOOR_FRAG)  # (a sphere's quad filled)
        d.program, d.vaos, d.errors, d.units, d.texel_world = program, [vao], np.zeros(1), [], {}
        if not hasattr(self, "copy"):
            self.copy = self.ctx.program(vertex_shader=_source("rects.vert", []), fragment_shader=COPY_FRAG)
            self.copy_vao = None

    def background_pass(self, rgba: np.ndarray) -> None:
        self.output.write(rgba)

    def tonemap_pass(self, *args) -> None:
        if self.tile is None:
            return
        self.tile.hdr.use(0)
        self.copy["hdr"].value = 0
        self.copy["origin"].value = self.rect[:2]
        self.copy["frame_size"].value = (self.camera.width, self.camera.height)
        self.copy["frame_height"].value = self.camera.height
        corners = np.array([[(x, y), (x + w, y), (x, y + h), (x, y + h), (x + w, y), (x + w, y + h)]
                            for x, y, w, h in self.rects], dtype="f4")
        if self.copy_vao is None:  # (a buffer kept, as the renderer keeps its own)
            self.copy_vbo = self.ctx.buffer(reserve=64 * 48)
            self.copy_vao = self.ctx.vertex_array(self.copy, [(self.copy_vbo, "2f", "in_corner")])
        self.copy_vbo.write(corners.tobytes())
        self.output_fbo.use()
        self.copy_vao.render(vertices=6 * len(self.rects))

    def overlay_pass(self, coverage: np.ndarray) -> None:
        if self.overlay_program is None:
            program = self.ctx.program(vertex_shader=_source("fullscreen.vert", []),
                                       fragment_shader=_source("overlay.frag", [f"BOX_ALPHA {OVERLAY_BOX_ALPHA}"]))
            texture = self.ctx.texture(coverage.shape[1::-1], 1, np.ascontiguousarray(coverage).tobytes(), dtype="f1")
            self.overlay_program = (program, self.ctx.vertex_array(program, []), texture)
        program, vao, texture = self.overlay_program
        self.output_fbo.use()
        self.ctx.enable(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        texture.use(0)
        program["image"].value = 0
        margin = max(self.camera.height // 90, 2)
        self.output_fbo.viewport = (margin, margin, *coverage.shape[1::-1])
        vao.render(vertices=3)
        self.ctx.disable(self.ctx.BLEND)
        self.output_fbo.viewport = (0, 0, self.camera.width, self.camera.height)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=180, help="frames spread over the path (default 180)")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--log-average", action="store_true", help="tone-map with the log-average (default: [render] log_average)")
    parser.add_argument("--scenario", help="a bundled scenario's name or a scenario TOML (default: the default scenario)")
    args = parser.parse_args()

    scenario = load_scenario(args.scenario)
    r = scenario.render
    log_average = args.log_average or r.log_average
    if args.scenario is None:
        env = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", 256)
    else:
        env = to_layout(load_environment(scenario.environment), "anglemap", 256)
    objects = light_objects(scene_objects(r, scenario.ar.table_albedo), env)
    exponents = sorted({1.0} | {o.material.exponent for o in objects})
    maps = MapSet.of("fast", exponents, fast_maps(env, exponents))
    ctx = create_gl_context()
    camera = CameraIntrinsics.from_fov(args.width, args.height, scenario.device.camera.hfov_deg)
    renderer, floor, least = Renderer(camera, maps, ctx), FloorRenderer(camera, maps, ctx), LeastRenderer(camera, maps, ctx)
    for obj in objects:
        for r_ in (renderer, floor, least):
            r_.add(obj)
    path = ar_path(scenario)
    t = np.linspace(0.0, path.duration, args.frames)
    t = t[path._away(t) == 0.0]  # the tag in view
    cam_to_world = path.camera_orientation(t)
    positions = path.position(t)
    background = np.random.default_rng(0).integers(0, 256, (args.height, args.width, 3), dtype=np.uint8)
    rgba = np.dstack([background, np.full(background.shape[:2], 255, np.uint8)])
    overlay = overlay_coverage(["frame 0  16.0 ms", "maps: fast"], args.height)
    query = ctx.query(time=True)
    names = ("background (4)", "objects (5)", "tone mapping (6)", "overlay (7)")
    warm = 3  # the first frames compile and allocate
    cpu, gl = np.zeros((3, len(t) + warm, 4)), np.zeros((3, len(t) + warm, 4))
    for n in range(len(t) + warm):
        k = max(n - warm, 0)
        rotation = cam_to_world[k].inv()
        translation = -rotation.apply(positions[k])

        def steps(r_):  # the renderer's steps 4-7 (its own, or the least shading's)
            return (lambda: r_.background_pass(rgba),  # (the session decodes its frames as RGBA: core.png.read_frame)
                    lambda: r_.render_objects(rotation, translation),
                    lambda: r_.tonemap_pass(r.key, r.white, log_average),
                    lambda: r_.overlay_pass([f"frame {k}  16.0 ms", "maps: fast"]))

        runs = (steps(renderer),
                (lambda: floor.background_pass(rgba),
                 lambda: floor.render_objects(rotation, translation),
                 lambda: floor.tonemap_pass(),
                 lambda: floor.overlay_pass(overlay)),
                steps(least))
        for which in np.roll([0, 1, 2], n % 3):  # (none always first)
            for s, work in enumerate(runs[which]):
                ctx.finish()
                start = time.perf_counter()
                with query:
                    work()
                ctx.finish()
                cpu[which, n, s], gl[which, n, s] = 1000 * (time.perf_counter() - start), query.elapsed / 1e6
    cpu, gl = cpu[:, warm:], gl[:, warm:]
    print(f"{args.width} x {args.height}, {len(renderer.objects)} objects, {len(t)} frames of the {args.scenario or 'default'} AR path "
          f"({np.linalg.norm(positions, axis=1).min():.2f}-{np.linalg.norm(positions, axis=1).max():.2f} m from the tag), "
          f"log_average {log_average}, ms:")
    print(f"  {'step':20s} {'CPU median':>10s} {'p95':>7s} {'max':>7s}   {'GL median':>9s} {'p95':>7s}   "
          f"{'floor median':>12s} {'p95':>7s} {'max':>7s}   {'median/floor':>12s}   {'least median':>12s} {'least/floor':>11s}")
    for s, name in enumerate(names + ("steps 4-7",)):
        c, g, f, m = ((cpu[0, :, s], gl[0, :, s], cpu[1, :, s], cpu[2, :, s]) if s < 4 else
                      (cpu[0].sum(axis=1), gl[0].sum(axis=1), cpu[1].sum(axis=1), cpu[2].sum(axis=1)))
        print(f"  {name:20s} {np.median(c):10.2f} {np.percentile(c, 95):7.2f} {c.max():7.2f}   "
              f"{np.median(g):9.2f} {np.percentile(g, 95):7.2f}   "
              f"{np.median(f):12.2f} {np.percentile(f, 95):7.2f} {f.max():7.2f}   {np.median(c) / np.median(f):12.2f}   "
              f"{np.median(m):12.2f} {np.median(m) / np.median(f):11.2f}")
    print("  (least: the renderer's steps with step 5 at the least shading Alg. 5.1 allows, two angle-map lookups a pixel "
          "on the floor's geometry)")


if __name__ == "__main__":
    main()
