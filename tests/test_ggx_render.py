"""GGX metallic-roughness materials in the renderer: the GL path against the NumPy reference
(render.shading.shade_ggx), the limits the split sum must reach (a mirror, a rough dielectric), the
scenario's keys, and Phong objects left as they were."""

import json

import numpy as np
import pytest

from arsim.core.conventions import CameraIntrinsics, normalize
from arsim.core.gl import create_gl_context
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import sample_anglemap, to_layout
from arsim.lighting.fast import fast_maps
from arsim.lighting.ggx import brdf_lut, sample_cube_lod
from arsim.lighting.mapset import MapSet
from arsim.render import shading
from arsim.render.content import ggx_chain, light_objects, scene_objects
from arsim.render.renderer import Material, Renderer, SceneObject
from arsim.render.meshes import uv_sphere
from arsim.scenario import ScenarioError, load_scenario
from arsim.scenario.loader import parse_scenario
from tests.conftest import ENVMAPS
from tests.test_render import look_at

CAMERA = CameraIntrinsics.from_fov(160, 120, 60.0)
EYE = np.array([0.05, 0.35, 0.3])
BASE = (0.9, 0.6, 0.3)


@pytest.fixture(scope="module")
def gl():
    return create_gl_context()


@pytest.fixture(scope="module")
def light():
    env = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 128)
    return env, MapSet.of("fast", (1.0, 80.0), fast_maps(env, (1.0, 80.0))), ggx_chain(env, 64)


def render(gl, maps, material, impostor=True, debug=True):
    """A sphere of radius 0.1 at (0, 0.1, 0), seen from EYE: the HDR colour, the mask, the normals and
    incident vectors GL shaded with."""
    r = Renderer(CAMERA, maps, gl, debug=debug)
    model = np.eye(4)
    model[:3, 3] = [0.0, 0.1, 0.0]
    r.add(SceneObject(uv_sphere(0.1), material, model, sphere=0.1 if impostor else None))
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    mask = r.read_mask() > 0.5
    normal, incident = r.read_debug()
    return r.read_hdr()[mask].astype(np.float64), mask, normal[mask][:, :3].astype(np.float64), incident[mask][:, :3].astype(np.float64)


def ggx(chain, roughness, metallic, base=BASE):
    return Material(exponent=1.0, model="ggx", base_color=base, metallic=metallic, roughness=roughness, ggx_chain=chain)


@pytest.mark.parametrize("roughness, metallic, impostor", [(0.0, 1.0, True), (0.3, 1.0, True), (0.5, 0.0, True),
                                                          (0.77, 0.5, False), (1.0, 0.0, True)])
def test_gl_ggx_equals_the_numpy_reference(gl, light, roughness, metallic, impostor):
    """Every pixel within the HDR target's precision (RGBA16F: 2^-10 of a value, llvmpipe's conversion
    truncating): measured at 160 x 120, mean relative error 3.5e-4, max 1.1e-3 (roughness 0, where level 0's
    sharp texels meet), silhouette included. Fractional levels (0.77 x 5 = 3.85) are trilinear as GL's."""
    env, maps, chain = light
    hdr, mask, n, v = render(gl, maps, ggx(chain, roughness, metallic), impostor)
    assert 0.1 < mask.mean() < 0.5
    reference = shading.shade_ggx(n, v, maps[1.0], chain, brdf_lut(), BASE, metallic, roughness)
    rel = np.abs(hdr - reference) / np.abs(reference)
    assert rel.mean() < 6e-4 and rel.max() < 3e-3


def test_gl_filters_the_rough_levels_across_the_faces_seams(gl, light):
    """At roughness 1 the level is 4 x 4 texels a face: a reference that clamps at the faces' edges (as
    lighting.ggx.sample_cube does for the prefilter's own reads) is off by up to 27 % near the seams, the
    seamless one within the HDR target's precision: GL's cube maps are seamless here, and so is the reference."""
    env, maps, chain = light
    hdr, mask, n, v = render(gl, maps, ggx(chain, 1.0, 1.0))
    r = shading.reflect(normalize(v), normalize(n))
    lod = np.full(len(r), len(chain) - 1.0)
    seamless, clamped = shading.sample_cube_chain(chain, r, lod), sample_cube_lod(chain, r, lod)
    assert np.abs(seamless - clamped).max() / np.abs(seamless).mean() > 0.05
    scale = shading.shade_ggx(n, v, maps[1.0], chain, brdf_lut(), BASE, 1.0, 1.0) / seamless
    assert (np.abs(hdr - scale * seamless) / (scale * seamless)).max() < 3e-3
    assert (np.abs(hdr - scale * clamped) / (scale * clamped)).max() > 0.05


def test_a_smooth_white_metal_is_a_mirror_of_the_probe(gl, light):
    """Roughness 0, metallic 1, base colour white: the probe itself in the reflected direction, times the
    split sum's A + B (1 within 1 % where n.v > 0.3, the table's first row being roughness 1/256): against
    the angle map looked up directly, the median pixel within 2 % (level 0 is the probe on 64 x 64 faces,
    each texel the mean of the angle map's texels in it)."""
    env, maps, chain = light
    hdr, mask, n, v = render(gl, maps, ggx(chain, 0.0, 1.0, (1.0, 1.0, 1.0)))
    n_dot_v = -np.sum(normalize(n) * normalize(v), axis=1)
    split = shading.sample_lut(brdf_lut(), n_dot_v, np.zeros(len(n)))
    assert np.abs(split.sum(axis=1)[n_dot_v > 0.3] - 1.0).max() < 0.01
    mirror = sample_anglemap(env, shading.reflect(normalize(v), normalize(n)))
    front = n_dot_v > 0.3
    rel = np.abs(hdr[front] - mirror[front]) / np.abs(mirror[front])
    assert np.median(rel) < 0.02


def test_a_rough_dielectric_is_lambertian_plus_a_small_fresnel_term(gl, light):
    """Roughness 1, metallic 0: the diffuse part base_color x the irradiance map, and on top a specular part
    that is small (F0 = 0.04) facing the camera and grows towards the silhouette (Fresnel)."""
    env, maps, chain = light
    hdr, mask, n, v = render(gl, maps, ggx(chain, 1.0, 0.0))
    diffuse = np.asarray(BASE) * sample_anglemap(maps[1.0], normalize(n))
    excess = (hdr - diffuse).mean(axis=1) / diffuse.mean(axis=1)
    n_dot_v = -np.sum(normalize(n) * normalize(v), axis=1)
    facing, grazing = n_dot_v > 0.8, n_dot_v < 0.2
    assert (excess > 0.0).all()
    assert 0.0 < np.median(excess[facing]) < 0.1
    assert np.median(excess[grazing]) > 1.5 * np.median(excess[facing])


def test_phong_pixels_stay_as_they_were_beside_a_ggx_object(gl, light):
    """A GGX object added to a renderer changes no pixel of a Phong object (its own shader variant)."""
    env, maps, chain = light
    phong = Material((0.6, 0.5, 0.4), (0.3, 0.3, 0.3), 80.0)
    alone, mask_alone, _, _ = render(gl, maps, phong)
    r = Renderer(CAMERA, maps, gl)
    model = np.eye(4)
    model[:3, 3] = [0.0, 0.1, 0.0]
    r.add(SceneObject(uv_sphere(0.1), phong, model, sphere=0.1))
    far = model.copy()
    far[:3, 3] = [0.3, 0.05, -0.3]  # (behind, to the side: not over the first sphere)
    r.add(SceneObject(uv_sphere(0.05), ggx(chain, 0.5, 1.0), far, sphere=0.05))
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    mask = r.read_mask() > 0.5
    assert mask.sum() > mask_alone.sum() + 50 and mask[mask_alone].all()
    assert np.array_equal(r.read_hdr()[mask_alone], alone.astype(np.float32))


def test_the_scenario_keys_make_ggx_objects_and_a_row_of_roughness(light):
    env, maps, chain = light
    s = parse_scenario('[[render.objects]]\nkind = "sphere_row"\nmaterial = "ggx"\nbase_color = [1.0, 0.77, 0.34]\n'
                       'metallic = 1.0\n[[render.objects]]\nkind = "sphere"\nmaterial = "ggx"\nroughness = 0.3\n'
                       '[[render.objects]]\nkind = "sphere"\n')
    objects = scene_objects(s.render)
    row, single, phong = objects[:10], objects[10], objects[11]
    assert [o.material.roughness for o in row] == pytest.approx(np.linspace(0.0, 1.0, 10))
    assert all(o.material.model == "ggx" and o.material.metallic == 1.0 and o.material.exponent == 1.0 for o in row)
    assert single.material.roughness == 0.3 and single.material.metallic == 0.0
    assert phong.material.model == "phong" and phong.material.exponent == s.render.objects[2].exponent
    lit = light_objects(objects, env)
    assert lit[0].material.ggx_chain is lit[10].material.ggx_chain is ggx_chain(env)  # one chain per light, cached
    assert lit[11].material.ggx_chain is None


@pytest.mark.parametrize("text, message", [
    ('material = "pbr"', r'material = "pbr" is not allowed: use one of "phong", "ggx"'),
    ("metallic = 1.5", r"metallic = 1.5 is out of range: allowed from 0.0 to 1.0"),
    ("roughness = -0.1", r"roughness = -0.1 is out of range"),
    ("base_color = [1.0, 0.5]", r"base_color = \[1.0, 0.5\] has the wrong type: expected an array of 3"),
])
def test_bad_ggx_keys_are_one_line_errors(tmp_path, text, message):
    path = tmp_path / "s.toml"
    path.write_text(f'[[render.objects]]\nkind = "sphere"\n{text}\n')
    with pytest.raises(ScenarioError, match=message) as info:
        load_scenario(path)
    assert "\n" not in str(info.value)


def test_a_ggx_material_without_its_cube_map_is_refused(gl, light):
    from arsim.core.errors import ArsimError

    env, maps, chain = light
    with pytest.raises(ArsimError, match="light the objects with content.light_objects"):
        Renderer(CAMERA, maps, gl).add(SceneObject(uv_sphere(0.1), ggx(None, 0.5, 0.0), np.eye(4), sphere=0.1))


def test_ggx_objects_without_a_probe_are_refused():
    from arsim.core.errors import ArsimError

    objects = scene_objects(parse_scenario('[[render.objects]]\nkind = "sphere"\nmaterial = "ggx"\n').render)
    with pytest.raises(ArsimError, match="give the probe"):
        light_objects(objects, None)


GGX_SESSION = """
[run]
seed = 4
[environment]
map = "{env}"
probe_size = 128
[capture]
duration_s = 1.0
[device.camera]
width = 160
height = 120
fps = 10.0
[ar]
duration_s = 2.0
near_m = 0.3
far_m = 0.5
[render]
flip_every = 1
[[render.objects]]
kind = "sphere_row"
size_m = 0.016
material = "ggx"
metallic = 1.0
[[render.objects]]
kind = "sphere"
position_m = [0.0, 0.06]
size_m = 0.02
material = "ggx"
roughness = 0.4
"""


def test_arsim_render_with_ggx_objects_matches_its_truth_frames(tmp_path):
    """End to end: the session lit by the true environment (--env) equals its truth frames, whose GGX chain
    is computed from the same light (FLIP 0), and only the irradiance map is baked for GGX objects."""
    from tests.test_cli import arsim

    (tmp_path / "s.toml").write_text(GGX_SESSION.format(env=ENVMAPS[1].as_posix()))
    r = arsim("render", tmp_path / "s.toml", "-o", tmp_path / "out", "--env", ENVMAPS[1], "--map-size", "64")
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["methods"] == {"fast": [1.0]}
    assert m["flip_frames"] > 0 and m["flip_mean"] == 0.0
