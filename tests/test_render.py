"""The renderer's GL path against its NumPy reference: image-based lighting with light and normal maps
in the HDR buffer, the masked Reinhard tone mapping in 8 bits, the mip-chain average; and light maps
and normal maps changing exactly the pixels they should."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.lighting.fast import fast_maps
from arsim.render import shading
from arsim.render.meshes import uv_sphere
from arsim.lighting.mapset import MapSet
from arsim.render.renderer import Material, Renderer, SceneObject
from tests.conftest import ENVMAPS

CAMERA = CameraIntrinsics.from_fov(320, 240, 60.0)
KD, KS = (0.6, 0.5, 0.4), (0.3, 0.3, 0.3)


@pytest.fixture(scope="module")
def gl():
    return create_gl_context()  # one context for every renderer here: a second would become the current one


@pytest.fixture(scope="module")
def maps():
    env = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 128)
    return MapSet.of("fast", (1.0, 80.0), fast_maps(env, (1.0, 80.0)))


def look_at(eye, target):
    """OpenCV world-to-camera rotation and translation of a camera at eye looking at target (y up)."""
    z = (np.asarray(target) - eye) / np.linalg.norm(np.asarray(target) - eye)
    x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    r = np.stack([x, np.cross(z, x), z])
    return Rotation.from_matrix(r), -r @ eye


def pixel_rays(eye, target) -> np.ndarray:
    """(H, W, 3) unit world directions of CAMERA's pixels, looking from eye at target (look_at)."""
    rotation, _ = look_at(eye, target)
    rows, cols = np.mgrid[0:CAMERA.height, 0:CAMERA.width]
    rays = np.stack([(cols - CAMERA.cx) / CAMERA.fx, (rows - CAMERA.cy) / CAMERA.fy, np.ones(rows.shape)], -1)
    rays = rotation.inv().apply(rays.reshape(-1, 3)).reshape(rays.shape)
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def bumps():
    """A tangent-space normal map (64 x 128): bumps in the left half of u, flat in the right half."""
    y, x = np.mgrid[0:64, 0:128]
    texel = np.zeros((64, 128, 3))
    texel[..., 0] = np.where(x < 64, 0.5 + 0.3 * np.sin(x / 3.0), 0.5)
    texel[..., 1] = np.where(x < 64, 0.5 + 0.3 * np.cos(y / 2.5), 0.5)
    texel[..., 2] = 1.0
    return texel


def shadow():
    """An ambient-occlusion light map (64 x 128): 0.3 in the upper half of v (rows at the top), 1 below."""
    return np.where(np.arange(64)[:, None, None] < 32, 0.3, 1.0) * np.ones((64, 128, 3))


EYE = np.array([0.05, 0.35, 0.3])


def render(gl, maps, material, debug=False, impostor=False):
    """A sphere of radius 0.1 at (0, 0.1, 0): a mesh, or (impostor) ray-cast through a quad."""
    r = Renderer(CAMERA, maps, gl, debug=debug)
    model = np.eye(4)
    model[:3, 3] = [0.0, 0.1, 0.0]
    r.add(SceneObject(uv_sphere(0.1), material, model, sphere=0.1 if impostor else None))
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    return r


@pytest.mark.parametrize("with_maps, impostor", [(False, False), (True, False), (False, True)])
def test_gl_shading_equals_the_numpy_reference(gl, maps, with_maps, impostor):
    """Shaded with the vectors GL interpolated (read back from debug targets), the NumPy equations give
    the HDR buffer within 1e-3 relative: RGBA16F holds 2^-10 of a value at worst, and llvmpipe's
    conversion to half floats truncates (half the pixels one step low): 9.8e-4 at most."""
    material = Material(KD, KS, 80.0, shadow() if with_maps else None, bumps() if with_maps else None)
    r = render(gl, maps, material, debug=True, impostor=impostor)
    hdr, mask = r.read_hdr(), r.read_mask() > 0.5
    normal, incident = r.read_debug()
    assert 0.03 < mask.mean() < 0.5
    light = normal[mask][:, 3:4].astype(np.float64) if with_maps else None
    reference = shading.shade(normal[mask][:, :3].astype(np.float64), incident[mask][:, :3].astype(np.float64),
                              maps[1.0], maps[80.0], np.array(KD), np.array(KS), light)
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3


@pytest.mark.parametrize("key, white, log_average", [(0.18, 2.0, False), (0.72, 0.8, False), (0.18, 2.0, True)])
def test_tone_mapping_equals_the_numpy_reference_within_one_step(gl, maps, key, white, log_average):
    r = render(gl, maps, Material(KD, KS, 80.0))
    background = np.random.default_rng(0).integers(0, 256, (CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
    out = r.tonemap(background, key, white, log_average)
    hdr, mask = r.read_hdr(), r.read_mask()
    # The average chain's top is the masked pixels' (log-)mean of the half-float colour, summed in float32.
    average = r.mip_average(log_average)
    assert average == pytest.approx(shading.average_luminance(hdr, mask, log_average), rel=1e-5)
    if log_average:  # the log-average lies below the mean (Jensen), for a scene with highlights well below
        assert average < 0.9 * shading.average_luminance(hdr, mask)
    reference = shading.tonemap(hdr, mask, key, white, average)
    inside = mask > 0.5
    expected = np.where(inside[..., None], np.clip(np.round(reference * 255), 0, 255), background)
    assert np.abs(out.astype(int) - expected.astype(int)).max() <= 1
    assert (out[~inside] == background[~inside]).all()  # the camera image passes where nothing is drawn


@pytest.mark.parametrize("log_average", [False, True])
def test_the_average_over_objects_far_apart_is_the_masked_mean_frame_after_frame(gl, maps, log_average):
    """Objects apart on the screen (their rectangles' corners off the average's blocks, the space between
    them never summed) and a second frame from elsewhere into the same tile: the tone mapper's average is
    the NumPy reference's over the frame's masked pixels within float32 rounding, and the tile holds
    nothing outside the frame's own rectangles (what the last frame wrote was cleared)."""
    from arsim.render.renderer import AVERAGE_BLOCK

    r = Renderer(CAMERA, maps, gl)
    for x, material in ((-0.25, Material(KD, KS, 80.0)), (0.25, Material((0.9, 0.2, 0.1), KS, 1.0))):
        model = np.eye(4)
        model[:3, 3] = [x, 0.1, 0.0]
        r.add(SceneObject(uv_sphere(0.1), material, model))  # meshes: two separate rectangles
    background = np.zeros((CAMERA.height, CAMERA.width, 3), np.uint8)
    tiles = []
    for eye in ([0.0, 0.3, 0.75], [0.06, 0.27, 0.8]):
        r.render_objects(*look_at(np.array(eye), [0.0, 0.1, 0.0]))
        r.tonemap(background, 0.18, 2.0, log_average)
        assert len(r.rects) == 2 and any(v % AVERAGE_BLOCK for rect in r.rects for v in rect)
        average = r.mip_average(log_average)
        assert average == pytest.approx(shading.average_luminance(r.read_hdr(), r.read_mask(), log_average), rel=1e-5)
        tiles.append(r.tile)
        w, h = r.tile.hdr.size
        tile = np.frombuffer(r.tile.hdr.read(), np.float16).reshape(h, w, 4)
        inside = np.zeros((h, w), bool)
        for x, y, rw, rh in r.rects:
            inside[y - r.rect[1]:y - r.rect[1] + rh, x - r.rect[0]:x - r.rect[0] + rw] = True
        assert (tile[~inside] == 0).all() and (tile[inside][:, 3] == 1).sum() > 500
    assert tiles[0] is tiles[1]  # the same tile, drawn elsewhere the second time


def test_a_ray_cast_sphere_has_the_exact_outline_and_normals(gl, maps):
    """The impostor's pixels are those whose rays hit the sphere (up to the pixels the outline crosses),
    and its normals are the sphere's at the hit, within float precision."""
    r = render(gl, maps, Material(KD, KS, 80.0), debug=True, impostor=True)
    mask = r.read_mask() > 0.5
    normal, incident = (v[..., :3].astype(np.float64) for v in r.read_debug())
    rays = pixel_rays(EYE, [0.0, 0.1, 0.0])
    centre, radius = np.array([0.0, 0.1, 0.0]), 0.1
    b = rays @ (EYE - centre)
    disc = b * b - (np.sum((EYE - centre) ** 2) - radius ** 2)
    hits = disc > 0
    from scipy.ndimage import binary_dilation, binary_erosion
    outline = binary_dilation(hits) & ~binary_erosion(hits)
    assert hits.sum() > 2000 and (mask == hits)[~outline].all()
    np.testing.assert_allclose(incident[mask], rays[mask], atol=2e-5)  # the same rays
    expected = (EYE + (-b - np.sqrt(np.maximum(disc, 0)))[..., None] * rays - centre) / radius
    assert np.abs(normal[mask] - expected[mask]).max() < 1e-4


def test_light_maps_and_normal_maps_change_exactly_their_pixels(gl, maps):
    plain = render(gl, maps, Material(KD, KS, 80.0), debug=True)
    lit = render(gl, maps, Material(KD, KS, 80.0, light_map=shadow()), debug=True)
    bumped = render(gl, maps, Material(KD, KS, 80.0, normal_map=bumps()), debug=True)
    mask = plain.read_mask() > 0.5
    base = plain.read_hdr()
    # The light map's value per pixel (debug w): 0.3 must darken the diffuse part, 1 must change nothing.
    light = lit.read_debug()[0][..., 3]
    dark, bright = mask & (light < 0.31), mask & (light > 1.0 - 1e-6)  # (0.999 would darken by 0.1 %)
    assert dark.sum() > 200 and bright.sum() > 200
    assert (lit.read_hdr()[dark] < 0.97 * base[dark]).all()
    # (a different shader variant: equal up to the HDR buffer's precision, one half-float step)
    np.testing.assert_allclose(lit.read_hdr()[bright], base[bright], rtol=1e-3, atol=0)
    # The normal map: its flat half (u > 0.5: longitudes pi..2 pi, world x < 0 on this sphere) keeps the
    # geometric normal and the pixels; its bumpy half turns them. Longitude from the geometric normal,
    # kept 0.6 rad (12 texels) from the halves' borders and away from the poles (where the longitudes
    # crowd, minification picks coarse mip levels) and from the silhouette (the same at grazing angles),
    # beyond the reach of the texture's filtering.
    n_plain, n_bumped = plain.read_debug()[0][..., :3], bumped.read_debug()[0][..., :3]
    turned = np.degrees(np.arccos(np.clip(np.sum(n_plain * n_bumped, -1), -1, 1)))
    longitude = np.arctan2(n_plain[..., 0], n_plain[..., 2])
    facing = -np.sum(n_plain * plain.read_debug()[1][..., :3], -1)
    band = mask & (np.abs(n_plain[..., 1]) < 0.7) & (facing > 0.3)
    east = band & (longitude > 0.6) & (longitude < np.pi - 0.6)
    west = band & (longitude < -0.6) & (longitude > -np.pi + 0.6)
    assert west.sum() > 200 and east.sum() > 200
    assert np.median(turned[east]) > 5.0 and np.mean(np.abs(bumped.read_hdr()[east] - base[east]) > 1e-3 * base[east]) > 0.5
    assert turned[west].max() < 0.1  # (coarse mip levels reach in from the bumpy half by a few hundredths)
    np.testing.assert_allclose(bumped.read_hdr()[west], base[west], rtol=1e-3, atol=0)


def test_the_torus_occlusion_is_open_on_top_and_closed_where_it_touches_the_table():
    from arsim.render.content import bake_torus_occlusion

    ao = bake_torus_occlusion(size=(32, 16), rays=64)[..., 0]
    row = (lambda v: 31 - int(v * 32))  # row 0 holds v = 1
    assert ao.min() >= 0.0 and ao.max() <= 1.0
    assert ao[row(0.25)].min() > 0.95  # the top of the ring sees the sky (this texel tilts 2 degrees to the hole)
    assert ao[row(0.75)].max() < 0.05  # its underside rests on the table
    # the inner equator faces the hole (the ring opposite, the table): darker than the outer one
    assert ao[row(0.5)].mean() < ao[row(0.01)].mean() - 0.1


def test_the_compiled_torus_occlusion_traces_as_the_numpy_sphere_trace():
    """The occlusion bake's compiled march counts, per origin, the rays that the NumPy sphere_trace (the
    oracle) finds hitting the torus or the table: on and above the torus and on the table, rays every way."""
    from arsim.render.content import _torus_scene_hits, scene_distance, sphere_trace, torus_texels

    major, minor = 0.05, 0.02
    point, normal, _ = torus_texels(major, minor, (8, 16))
    rng = np.random.default_rng(4)
    origins = np.concatenate([(point + normal * 1e-3 * minor).reshape(-1, 3),
                              rng.uniform([-0.1, 0.0005, -0.1], [0.1, 0.06, 0.1], (64, 3))])
    directions = rng.normal(size=(32, len(origins), 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    reach = 6.0 * (major + minor)
    expected = sphere_trace(origins, directions, lambda p: scene_distance(p, major, minor), minor, reach).sum(axis=0)
    assert 0 < expected.sum() < directions.shape[0] * len(origins)  # (some rays hit, some escape)
    np.testing.assert_array_equal(_torus_scene_hits(origins, directions, major, minor, reach, 96), expected)


def test_vertex_tangents_follow_increasing_u():
    """Tangents from the UVs (Lengyel) equal the parametric surfaces' own: east on a sphere (away from
    its poles, where longitudes meet), along the ring on the torus; on the seam, where a vertex has
    triangles on one side only, within half a segment's turn."""
    from arsim.render.content import torus
    from arsim.render.meshes import vertex_tangents

    for mesh in (uv_sphere(1.0, 24, 48), torus(0.05, 0.02, 48, 24)):
        computed = vertex_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
        inner = np.abs(mesh.normals[:, 1]) < 0.95
        seam = (mesh.uvs[:, 0] == 0.0) | (mesh.uvs[:, 0] == 1.0)
        cos = np.sum(computed * mesh.tangents, axis=1)
        assert cos[inner & ~seam].min() > 0.9999
        assert cos[inner & seam].min() > np.cos(np.pi / 48)  # both meshes: 48 segments around
        assert np.abs(np.sum(computed * mesh.normals, axis=1)).max() < 1e-5  # orthogonal to the normal


def test_a_mesh_file_renders_like_the_mesh_it_holds(gl, maps, tmp_path):
    """A torus written to OBJ with its UVs and read back: same triangles, UVs kept, and the same pixels."""
    import trimesh

    from arsim.render.content import torus
    from arsim.render.meshes import load_mesh

    mesh = torus(0.1, 0.04, 48, 24)
    visual = trimesh.visual.TextureVisuals(uv=mesh.uvs)
    trimesh.Trimesh(mesh.positions, mesh.indices, vertex_normals=mesh.normals, visual=visual, process=False).export(
        tmp_path / "t.obj", include_normals=True)
    loaded, textured = load_mesh(tmp_path / "t.obj")
    assert textured and len(loaded.indices) == len(mesh.indices)
    material = Material(KD, KS, 80.0, normal_map=bumps())
    images = []
    for m in (mesh, loaded):
        r = Renderer(CAMERA, maps, gl)
        r.add(SceneObject(m, material))
        r.render_objects(*look_at(np.array([0.05, 0.35, 0.3]), [0.0, 0.03, 0.0]))
        images.append((r.read_hdr(), r.read_mask() > 0.5))
    (a, mask_a), (b, mask_b) = images
    assert mask_a.mean() > 0.05 and (mask_a == mask_b).mean() > 0.999  # (the OBJ's 6-digit vertices: edge pixels)
    both = mask_a & mask_b
    assert np.median(np.abs(a[both] - b[both]) / np.maximum(b[both], 1e-3)) < 1e-3


def test_each_material_takes_its_own_methods_maps(gl, maps):
    """Two methods' maps in one renderer: a material naming one is lit by it; a method without the
    material's exponent is refused."""
    from arsim.core.errors import ArsimError

    dim = MapSet("mipmap", {s: m * 0.5 for s, m in maps.maps.items()})  # a second method, its maps half as bright
    view = look_at(np.array([0.05, 0.35, 0.3]), [0.0, 0.1, 0.0])
    model = np.eye(4)
    model[:3, 3] = [0.0, 0.1, 0.0]
    images = {}
    for method in ("fast", "mipmap"):
        r = Renderer(CAMERA, [maps, dim], gl, method="fast")
        r.add(SceneObject(uv_sphere(0.1), Material(KD, KS, 80.0, method=method), model))
        r.render_objects(*view)
        images[method] = r.read_hdr()
    inside = r.read_mask() > 0.5
    np.testing.assert_allclose(images["mipmap"][inside], 0.5 * images["fast"][inside], rtol=2e-3)
    r = Renderer(CAMERA, [maps, MapSet("mipmap", {1.0: dim[1.0]})], gl)
    with pytest.raises(ArsimError, match="no mipmap maps for exponent 80"):
        r.add(SceneObject(uv_sphere(0.1), Material(KD, KS, 80.0, method="mipmap"), model))


@pytest.mark.parametrize("spec, terms", [("modh6", None), ("modh6", 1), ("sh9", 4), ("hsh9", None), ("zernike6", None)])
def test_irradiance_normal_mapping_equals_the_numpy_reference(gl, maps, spec, terms):
    """A directional light map in each basis on a normal-mapped sphere (diffuse only): GL against
    shading.inm_diffuse at the tangent-space normal and light-map coordinates GL interpolated (debug
    targets), the coefficients looked up as GL does (bilinear, repeating, level 0 at this distance)."""
    from arsim.evaluate.inm_compare import sample_periodic
    from arsim.lighting.bases import parse_basis

    count = parse_basis(spec)[1]
    rng = np.random.default_rng(4)
    coefficients = rng.uniform(-0.5, 0.5, (16, 32, count, 3))
    coefficients[:, :, 0] = rng.uniform(2.0, 3.0, (16, 32, 3))  # a positive constant term dominates
    material = Material(KD, (0.0, 0.0, 0.0), 80.0, normal_map=bumps(), directional_map=coefficients, basis=spec,
                        inm_terms=terms)
    r = render(gl, maps, material, debug=True)
    hdr, mask = r.read_hdr(), r.read_mask() > 0.5
    normal, incident = (v.astype(np.float64) for v in r.read_debug())
    assert 0.03 < mask.mean() < 0.5
    uv2 = np.stack([normal[mask][:, 3], incident[mask][:, 3]], axis=-1)
    at_texels = sample_periodic(coefficients, uv2)
    reference = np.array(KD) * shading.inm_diffuse(at_texels, spec, normal[mask][:, :3], terms)
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3, rel.max()  # (RGBA16F, as test_gl_shading_equals_the_numpy_reference)


def test_a_directional_light_map_of_the_wrong_shape_is_refused(gl, maps):
    from arsim.core.errors import ArsimError

    with pytest.raises(ArsimError, match="modh6 directional light map holds"):
        render(gl, maps, Material(KD, KS, 80.0, directional_map=np.zeros((8, 8, 4, 3)), basis="modh6"))
    with pytest.raises(ArsimError, match="unknown basis"):
        render(gl, maps, Material(KD, KS, 80.0, directional_map=np.zeros((8, 8, 4, 3)), basis="nope4"))


@pytest.mark.parametrize("impostor", [False, True])
def test_an_irradiance_volume_equals_the_numpy_reference(gl, maps, impostor):
    """A sphere lit through an irradiance volume (diffuse only): GL against shading.volume_diffuse at the
    world points and normals GL shaded (debug targets)."""
    rng = np.random.default_rng(7)
    coefficients = rng.uniform(-0.3, 0.3, (4, 3, 5, 9, 3))
    coefficients[..., 0, :] = rng.uniform(3.0, 4.0, (4, 3, 5, 3))
    volume = (coefficients, np.array([-0.15, 0.0, -0.12]), np.array([0.15, 0.22, 0.12]))
    r = render(gl, maps, Material(KD, (0.0, 0.0, 0.0), 80.0, irradiance_volume=volume), debug=True, impostor=impostor)
    hdr, mask = r.read_hdr(), r.read_mask() > 0.5
    normal, point = (v[..., :3].astype(np.float64) for v in r.read_debug())
    assert 0.03 < mask.mean() < 0.5
    reference = np.array(KD) * shading.volume_diffuse(volume, point[mask], normal[mask])
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3, rel.max()  # (RGBA16F, as test_gl_shading_equals_the_numpy_reference)


@pytest.mark.parametrize("impostor", [False, True])
def test_an_object_that_moves_is_drawn_where_its_orbit_has_it(gl, maps, impostor):
    """A sphere going round a circle of 0.08 in 4 s about (0, 0.1, 0): at 0 s and at 1 s it is drawn as the
    same sphere standing at +z and at +x of that point (to the last bit), and the renderer's rectangles
    follow it."""
    from arsim.render.renderer import Orbit

    def frame(offset, orbit=None, time_s=0.0):
        r = Renderer(CAMERA, maps, gl)
        model = np.eye(4)
        model[:3, 3] = np.array([0.0, 0.1, 0.0]) + offset
        r.add(SceneObject(uv_sphere(0.05), Material(KD, KS, 80.0), model, sphere=0.05 if impostor else None, orbit=orbit))
        r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]), time_s=time_s)
        return np.dstack([r.read_hdr(), r.read_mask()]), r.rect

    orbit = Orbit(0.08, 4.0)
    for time_s, offset in ((0.0, [0.0, 0.0, 0.08]), (1.0, [0.08, 0.0, 0.0])):
        moving, rect = frame(np.zeros(3), orbit, time_s)
        still, still_rect = frame(np.array(offset))
        assert rect == still_rect and (moving[..., 3] > 0.5).sum() > 500
        np.testing.assert_array_equal(moving, still)
    # (the two times differ: the test sees the motion)
    assert not np.array_equal(frame(np.zeros(3), orbit, 0.0)[0], frame(np.zeros(3), orbit, 1.0)[0])


def test_rectangles_side_by_side_merge_and_rectangles_apart_do_not():
    from arsim.render.renderer import merge_rects

    row = [(100 + 70 * k, 500 + k % 2, 75, 80) for k in range(10)]  # a row of spheres' rectangles, overlapping
    apart = (400, 100, 300, 250)
    merged = merge_rects(row + [apart])
    assert merged == [(100, 500, 705, 81), apart]
    assert merge_rects([(0, 0, 10, 10), (30, 0, 10, 10)]) == [(0, 0, 10, 10), (30, 0, 10, 10)]  # 40 x 10 over 200 covered
    covered = np.zeros((800, 1000), bool)
    for x, y, w, h in row + [apart]:
        covered[y:y + h, x:x + w] = True
    inside = np.zeros_like(covered)
    for x, y, w, h in merged:
        inside[y:y + h, x:x + w] = True
    assert inside[covered].all() and inside.sum() <= 1.25 * covered.sum()


def test_the_torus_levels_of_detail_depart_from_the_torus_by_what_they_state():
    """Each coarser torus's stated departure bounds how far its triangles lie from the surface (at their
    centres and edge midpoints) and is not loose (at most twice it); the steps are close, so that the
    renderer's half-pixel limit picks a mesh little finer than it needs."""
    from arsim.render.content import torus_distance, torus_lods

    lods = torus_lods(0.05, 0.02, 96)
    errors = np.array([e for _, e in lods])
    assert (np.diff(errors) > 0).all() and (errors[1:] / errors[:-1]).max() < 1.6
    for mesh, error in lods:
        p = mesh.positions[mesh.indices].astype(np.float64)  # (T, 3, 3)
        points = np.concatenate([p.mean(axis=1), ((p + np.roll(p, 1, axis=1)) / 2).reshape(-1, 3)])
        departure = np.abs(torus_distance(points, 0.05, 0.02)).max()
        assert 0.5 * error <= departure <= error * (1 + 1e-4)


TORUS_EYE = np.array([0.12, 0.2, 0.26])


def torus_model():
    """The torus turned, tipped and scaled 1.5 times (the ray goes into object space through all three)."""
    model = np.eye(4)
    model[:3, :3] = 1.5 * Rotation.from_euler("yx", [35.0, 15.0], degrees=True).as_matrix()
    model[:3, 3] = [0.0, 0.01, 0.0]
    return model


def render_torus(gl, maps, material, impostor):
    """The torus (0.05, 0.02) of torus_model from TORUS_EYE, with debug targets: ray-cast through its proxy, or
    its 96 x 48 mesh."""
    from arsim.render.content import torus, torus_proxy

    r = Renderer(CAMERA, maps, gl, debug=True)
    r.add(SceneObject(torus(0.05, 0.02), material, torus_model(),
                      torus=(0.05, 0.02, torus_proxy(0.05, 0.02)) if impostor else None))
    r.render_objects(*look_at(TORUS_EYE, [0.0, 0.03, 0.0]))
    return r


def test_a_ray_cast_torus_has_the_exact_outline_and_normals(gl, maps):
    """The torus ray-cast through its proxy: its pixels are those whose rays hit the torus (sphere tracing
    of its exact distance, float64), up to the pixels the outline crosses, and its normals are the torus's
    at the hit (the traced hit polished on the torus's quartic)."""
    from scipy.ndimage import binary_dilation, binary_erosion

    from arsim.render.content import sphere_trace, torus_distance

    r = render_torus(gl, maps, Material(KD, KS, 80.0), impostor=True)
    mask = r.read_mask() > 0.5
    normal, incident = (v[..., :3].astype(np.float64) for v in r.read_debug())
    rays = pixel_rays(TORUS_EYE, [0.0, 0.03, 0.0])
    inverse = np.linalg.inv(torus_model())
    origin = inverse[:3, :3] @ TORUS_EYE + inverse[:3, 3]
    directions = rays @ inverse[:3, :3].T  # (object lengths: 1 / 1.5 of the world's)
    along = sphere_trace(origin, directions / np.linalg.norm(directions, axis=-1, keepdims=True),
                         lambda p: torus_distance(p, 0.05, 0.02), 0.02, 1.0, steps=400, distances=True)
    hits = np.isfinite(along)
    outline = binary_dilation(hits) & ~binary_erosion(hits)
    assert hits.sum() > 3000 and (mask == hits)[~outline].all()
    np.testing.assert_allclose(incident[mask], rays[mask], atol=2e-5)  # the same rays
    # The traced hits (within 1e-4 of the minor radius of the surface, along a grazing ray further) polished by
    # Newton's method on the torus's quartic, (|p|^2 + R^2 - r^2)^2 - 4 R^2 (p_x^2 + p_z^2), in float64.
    d = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    o = origin - [0.0, 0.02, 0.0]
    t = np.where(hits, along, 0.0)
    for _ in range(4):
        p = o + t[..., None] * d
        inner = np.sum(p * p, axis=-1) + 0.05**2 - 0.02**2
        f = inner**2 - 4 * 0.05**2 * (p[..., 0] ** 2 + p[..., 2] ** 2)
        df = 4 * inner * np.sum(p * d, axis=-1) - 8 * 0.05**2 * (p[..., 0] * d[..., 0] + p[..., 2] * d[..., 2])
        t = t - np.where(hits, f / np.where(df == 0, 1.0, df), 0.0)
    point = o + t[..., None] * d + [0.0, 0.02, 0.0]
    ring = point * [1.0, 0.0, 1.0]
    ring /= np.linalg.norm(ring, axis=-1, keepdims=True)
    expected = point - (0.05 * ring + [0.0, 0.02, 0.0])  # from the tube's centre line
    expected = expected @ inverse[:3, :3]  # the normal matrix (inverse transpose) applied
    expected /= np.linalg.norm(expected, axis=-1, keepdims=True)
    both = mask & hits
    gap = np.abs(normal - expected).max(axis=-1)
    # float32 roots: 1e-6 where the ray meets the surface squarely, about its square root where it grazes it
    assert np.median(gap[both]) < 1e-5 and gap[both & ~outline].max() < 1e-4 and gap[both].max() < 1e-3


def test_a_ray_cast_torus_reads_its_maps_where_its_mesh_does(gl, maps):
    """The ray-cast torus's UVs and tangents are its mesh's: a light map that varies along both u and v, and
    a normal map bumped on one half of u, give the ray-cast torus the values the mesh interpolates, inside
    the outline (within the mesh's own departure from the torus)."""
    from scipy.ndimage import binary_erosion

    v, u = np.mgrid[0:64, 0:128] / np.array([64.0, 128.0])[:, None, None]
    light = np.repeat((0.5 + 0.3 * np.sin(2 * np.pi * u) + 0.15 * np.sin(2 * np.pi * v))[..., None], 3, axis=-1)
    images = {}
    for impostor in (False, True):
        r = render_torus(gl, maps, Material(KD, KS, 80.0, light, bumps()), impostor)
        images[impostor] = (r.read_mask() > 0.5, r.read_debug()[0].astype(np.float64))
    inside = binary_erosion(images[False][0] & images[True][0], iterations=2)
    assert inside.sum() > 3000
    (_, mesh), (_, cast) = images[False], images[True]
    light_gap = np.abs(cast[inside, 3] - mesh[inside, 3])
    normal_gap = np.degrees(np.arccos(np.clip(np.sum(cast[inside, :3] * mesh[inside, :3], -1), -1.0, 1.0)))
    # (measured: light 1.2e-4 median, 1.5e-3 at most; normals 0.09 degrees median, 0.6 at the 99th percentile)
    assert np.median(light_gap) < 1e-3 and light_gap.max() < 0.01
    assert np.median(normal_gap) < 0.3 and np.percentile(normal_gap, 99) < 2.0


def test_the_torus_proxy_holds_the_torus():
    """Every point of the torus (and just outside it) lies inside its proxy mesh (winding number 1), for tori
    thin and thick; a torus whose proxy would reach the axis has none (it is drawn as its mesh)."""
    from arsim.render.content import torus_proxy, torus_surface

    for major, minor in ((0.05, 0.02), (0.05, 0.04), (0.05, 0.005), (1.0, 0.3)):
        proxy = torus_proxy(major, minor)
        triangles = proxy.positions[proxy.indices].astype(np.float64)
        u, v = np.meshgrid(np.linspace(0.0, 1.0, 121), np.linspace(0.0, 1.0, 61), indexing="ij")
        point, normal, _ = torus_surface(u, v, major, minor)
        points = (point + 1e-3 * minor * normal).reshape(-1, 3)
        a, b, c = (triangles[:, k][None] - points[:, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        dot = lambda x, y: np.einsum("pti,pti->pt", x, y)
        solid = 2.0 * np.arctan2(dot(a, np.cross(b, c)), la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb)
        np.testing.assert_allclose(solid.sum(axis=1) / (4.0 * np.pi), 1.0, atol=1e-6)
    assert torus_proxy(1.0, 0.9) is None


def test_an_rgba_camera_frame_is_the_background_an_rgb_one_is(gl, maps):
    """Step 4 uploads an RGBA frame (as the session decodes them) as it is, and converts an RGB one: the same
    output to the byte, with the objects tone-mapped over either."""
    frame = np.random.default_rng(5).integers(0, 256, (CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
    r = render(gl, maps, Material(KD, KS, 80.0))
    outputs = []
    for background in (frame, np.dstack([frame, np.full(frame.shape[:2], 255, np.uint8)])):
        r.background_pass(background)
        r.tonemap_pass()
        outputs.append(r.read_output())
    assert (outputs[0] != frame).any()  # (the sphere is drawn over it)
    assert np.array_equal(outputs[0], outputs[1])


@pytest.mark.parametrize("height", [240, 720])
def test_the_overlay_drawn_from_its_coverage_is_its_image_blended(gl, maps, height):
    """Step 7 uploads only the text's coverage and its shader makes overlay_image's colour and alpha from it:
    the frame is overlay_image blended over it (within one code: GL's blend rounds), nothing outside the box
    changes."""
    from arsim.render.renderer import overlay_image

    camera = CameraIntrinsics.from_fov(height * 4 // 3, height, 60.0)
    lines = ["frame 1234  16.0 ms", "maps: fast; baking accurate 47 %"]
    frame = np.random.default_rng(height).integers(0, 256, (camera.height, camera.width, 3), dtype=np.uint8)
    r = Renderer(camera, maps, gl)
    r.background_pass(frame)
    r.overlay_pass(lines)
    out = r.read_output().astype(float)
    image = overlay_image(lines, height).astype(float)
    margin, (h, w) = max(height // 90, 2), image.shape[:2]
    assert r.overlay_box == np.s_[margin:margin + h, margin:margin + w]
    assert (image[..., 0] > 0).mean() > 0.05  # (text drawn)
    expected = frame.astype(float)
    alpha = image[..., 3:] / 255.0
    expected[r.overlay_box] = image[..., :3] * alpha + expected[r.overlay_box] * (1.0 - alpha)
    assert np.abs(out - expected).max() <= 1.0
    outside = np.ones(frame.shape[:2], bool)
    outside[r.overlay_box] = False
    assert np.array_equal(out[outside], frame[outside])
