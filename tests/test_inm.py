"""Directional light maps and irradiance volumes (irradiance normal mapping, spec 2.2): the bake's
plumbing against an independent route, visibility, 8-bit storage, and a normal-mapped torus lit through
a modified-H light map against the per-pixel reference and the thesis's AO light map."""

import dataclasses

import numpy as np
import pytest

from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.evaluate.inm_compare import compare_on_torus, scores
from arsim.lighting.bases import get_basis, project, reconstruct
from arsim.lighting.bases.functions import sh9
from arsim.lighting.bases.irradiance import irradiance, sh9_irradiance_coefficients
from arsim.lighting.bases.lightmap import (
    Surface,
    bake_directional,
    bake_irradiance_volume,
    decode_8bit,
    encode_8bit,
    probe_samples,
    sample_volume,
    volume_irradiance,
)
from arsim.lighting.bases.quadrature import hemisphere_quadrature
from tests.conftest import ENVMAPS


@pytest.fixture(scope="module")
def samples():
    return probe_samples(to_layout(read_hdr(ENVMAPS[1]), "anglemap", 24))


def _tilted_surface():
    """Two texels with different frames: a tilted one and a flat one."""
    n = np.array([[[0.0, 1.0, 0.0], [0.6, 0.8, 0.0]]])
    t = np.array([[[1.0, 0.0, 0.0], [0.8, -0.6, 0.0]]])
    return Surface(np.zeros((1, 2, 3)), n, t, np.ones((1, 2), bool))


@pytest.mark.parametrize("spec", [("modh", 6), ("h", 6), ("sh", 9), ("hsh", 9), ("zernike", 6)])
def test_a_texels_coefficients_fit_its_irradiance_in_its_tangent_frame(samples, spec):
    basis, count = get_basis(spec[0]), spec[1]
    directions, weighted = samples
    surface = _tilted_surface()
    direct = bake_directional(surface, basis, count, directions, weighted)
    via_sh9 = bake_directional(surface, basis, count, directions, weighted, route="sh9")
    d, w = hemisphere_quadrature()

    def error(c, exact):  # squared error over the hemisphere of normals, relative
        return float(((reconstruct(basis, count, c, d) - exact) ** 2 * w[:, None]).sum() / (exact ** 2 * w[:, None]).sum())

    for k in range(2):
        n, t = surface.normals[0, k], surface.tangents[0, k]
        frame = np.stack([t, np.cross(n, t), n])  # rows: tangent-space axes in world
        local = directions @ frame.T
        # the spec's route: the radiance's SH (below the horizon dropped) convolved, then fitted
        coeffs = sh9_irradiance_coefficients(local, weighted)
        np.testing.assert_allclose(via_sh9[0, k], project(basis, count, sh9(d) @ coeffs, d, w), rtol=1e-9, atol=1e-12)
        # the direct route: as close to the exact irradiance as the basis's best fit (on a finer rule)
        exact = irradiance(d, local, weighted)
        best = error(project(basis, count, exact, d, w), exact)
        assert error(direct[0, k], exact) < 1.02 * best


def test_a_texel_under_a_roof_gets_no_light(samples):
    directions, weighted = samples
    surface = _tilted_surface()
    baked = bake_directional(surface, get_basis("modh"), 6, directions, weighted,
                             blocked=lambda o, d: np.ones(d.shape[:-1], bool))
    assert not baked.any()
    half = bake_directional(surface, get_basis("modh"), 6, directions, weighted,
                            blocked=lambda o, d: d[..., 0] > 0)  # a wall on the +x side
    full = bake_directional(surface, get_basis("modh"), 6, directions, weighted)
    assert 0 < half[0, 0, 0].mean() < full[0, 0, 0].mean()


def test_an_unoccluded_irradiance_volume_is_the_environments_sh_irradiance_everywhere(samples):
    directions, weighted = samples
    grid = np.stack(np.meshgrid(*[np.linspace(-0.1, 0.1, 3)] * 3, indexing="ij"), -1)
    volume = bake_irradiance_volume(grid, directions, weighted)
    expected = sh9(directions).T @ weighted * np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)[:, None]
    np.testing.assert_allclose(volume, np.broadcast_to(expected, volume.shape), rtol=1e-12)
    # a table below: the lower hemisphere is dark, so a normal pointing down sees less light
    shadowed = bake_irradiance_volume(grid, directions, weighted, blocked=lambda o, d: d[..., 1] < 0)
    down, up = np.array([0.0, -1.0, 0.0]), np.array([0.0, 1.0, 0.0])
    c = sample_volume(shadowed, np.full(3, -0.1), np.full(3, 0.1), np.array([0.03, 0.0, -0.02]))
    assert (volume_irradiance(c, down) < volume_irradiance(c, up)).all()


def test_volume_lookup_is_trilinear():
    axis = np.linspace(0.0, 1.0, 4)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    volume = np.repeat((grid @ [1.0, 2.0, 3.0])[..., None, None], 9, axis=-2).repeat(3, axis=-1)
    points = np.random.default_rng(0).uniform(0, 1, (20, 3))
    np.testing.assert_allclose(sample_volume(volume, np.zeros(3), np.ones(3), points)[:, 0, 0], points @ [1.0, 2.0, 3.0])


def test_8bit_storage_keeps_coefficients_within_its_quantisation():
    rng = np.random.default_rng(0)
    c = np.concatenate([rng.uniform(0.05, 1.0, (50, 1, 3)), rng.uniform(-0.7, 0.7, (50, 5, 3))], axis=1) * 2.0
    back = decode_8bit(encode_8bit(c, 2.0), 2.0)
    assert np.abs(back[:, 1:] - c[:, 1:]).max() <= 2.0 * 0.75 / 255 + 1e-12  # half a step of the [-0.75, 0.75] range
    assert (np.abs(back[:, 0] - c[:, 0]) / c[:, 0]).max() < 0.06  # gamma 1/2.2: relative steps, largest at the dark end


@pytest.mark.parametrize("envmap", ["interior.exr", "sunrise.exr"])
def test_a_modified_h_light_map_is_closer_to_the_per_pixel_reference_than_the_ao_light_map(envmap):
    probe = to_layout(read_hdr(next(p for p in ENVMAPS if p.name == envmap)), "anglemap", 64)
    result = scores(compare_on_torus(probe, [(get_basis("modh"), 6, False)], width=64, height=48,
                                     lightmap_size=(16, 32), light_size=24))
    assert result["modh6"]["flip"] < result["thesis"]["flip"]
    assert result["modh6"]["mse"] < result["thesis"]["mse"]


def _objects(tmp_path, extra: str = ""):
    from arsim.render.content import scene_objects
    from arsim.scenario import load_scenario

    path = tmp_path / "inm.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "inm-modh6"\nlightmap_size = 8\n'
                    '[[render.objects]]\nkind = "disc"\nsize_m = 0.12\nlighting = "inm-h4"\nlightmap_size = 12\n' + extra)
    return scene_objects(load_scenario(path).render)


def test_scenario_objects_get_directional_light_maps_baked_from_the_light(tmp_path):
    from arsim.render.content import light_objects

    objects = _objects(tmp_path)
    assert [o.material.basis for o in objects] == ["modh6", "h4"]
    assert all(o.material.directional_map is None for o in objects)
    light = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32)
    torus, disc = light_objects(objects, light)
    assert torus.material.directional_map.shape == (8, 16, 6, 3) and disc.material.directional_map.shape == (12, 12, 4, 3)
    # contact shadow: on the disc, the constant term where the torus's tube touches it (0.05 m from the
    # centre) is far darker than near the disc's rim
    constant = disc.material.directional_map[..., 0, :].mean(axis=-1)
    centres = ((np.arange(12) + 0.5) / 12 * 2 - 1) * 0.12
    radius = np.hypot(*np.meshgrid(centres, centres, indexing="ij"))
    under_tube = constant[(radius > 0.04) & (radius < 0.06)].mean()
    outside = constant[(radius > 0.09) & (radius < 0.12)].mean()
    assert under_tube < 0.3 * outside, (under_tube, outside)


@pytest.mark.parametrize("lighting, fragment", [
    ("inm-nosuch4", "unknown basis 'nosuch'"),
    ("inm-h5", "has 4 or 6 coefficients, not 5"),
    ("shiny", "use ibl, lightmap-ao, volume, inm-BASIS"),
    ("shiny", "or prt-VARIANT (prt-gs, prt-sep, prt-sep-c, prt-hl2, prt-sal)"),
    ("prt-nosuch", "unknown PRT variant 'nosuch'"),
])
def test_a_bad_lighting_is_refused_in_one_line(tmp_path, lighting, fragment):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text(f'[[render.objects]]\nkind = "torus"\nlighting = "{lighting}"\n')
    assert_one_line_error(arsim("render", path, "-o", tmp_path / "out"), fragment)


def test_a_light_map_size_of_zero_is_refused_in_one_line(tmp_path):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "inm-modh6"\nlightmap_size = 0\n')
    assert_one_line_error(arsim("validate", path), "lightmap_size")


def test_more_terms_than_the_basis_has_are_refused_in_one_line(tmp_path):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "inm-h4"\ninm_terms = 6\n')
    assert_one_line_error(arsim("render", path, "-o", tmp_path / "out"), "inm_terms = 6")


def test_objects_that_move_are_lit_through_the_scenes_irradiance_volume(tmp_path):
    from arsim.render.content import VOLUME_GRID, light_objects, scene_objects
    from arsim.scenario import load_scenario

    path = tmp_path / "volume.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "ibl"\n'
                    '[[render.objects]]\nkind = "sphere"\nposition_m = [0.12, 0.0]\nsize_m = 0.02\nlighting = "volume"\n')
    torus, sphere = light_objects(scene_objects(load_scenario(path).render), to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32))
    assert torus.material.irradiance_volume is None and sphere.material.volume_lit
    coefficients, low, high = sphere.material.irradiance_volume
    assert coefficients.shape == VOLUME_GRID + (9, 3)
    assert low[0] < -0.07 and high[0] > 0.14  # the box holds both objects
    # beside the torus, near the table: a normal facing the torus gets less light than one facing away
    c = sample_volume(coefficients, low, high, np.array([0.085, 0.01, 0.0]))
    toward, away = volume_irradiance(c, np.array([-1.0, 0.0, 0.0])), volume_irradiance(c, np.array([1.0, 0.0, 0.0]))
    assert toward.mean() < 0.8 * away.mean(), (toward, away)


def test_the_volume_holds_an_orbiting_object_wherever_it_goes_and_it_occludes_nothing(tmp_path):
    """A sphere going round the torus at 0.1 m: the volume's box holds its whole circle, and a grid point
    on its circle sees the torus's occlusion only (the sphere, which moves, casts no baked shadow)."""
    from arsim.render.content import light_objects, scene_objects
    from arsim.scenario import load_scenario

    path = tmp_path / "orbit.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "ibl"\n'
                    '[[render.objects]]\nkind = "sphere"\nsize_m = 0.02\nlighting = "volume"\norbit_m = 0.1\n')
    light = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32)
    torus, sphere = scene_objects(load_scenario(path).render)
    assert sphere.orbit is not None and sphere.orbit.radius == 0.1
    _, moving = light_objects([torus, sphere], light)
    coefficients, low, high = moving.material.irradiance_volume
    assert (low[[0, 2]] <= -0.12 + 1e-9).all() and (high[[0, 2]] >= 0.12 - 1e-9).all()
    # the same as with no distance function for the sphere: it occludes nothing
    _, ghost = light_objects([torus, dataclasses.replace(sphere, distance=None)], light)
    np.testing.assert_array_equal(ghost.material.irradiance_volume[0], coefficients)
    # and the torus does: below its top, the side of the circle's grid facing the torus gets less light
    c = sample_volume(coefficients, low, high, np.array([0.1, 0.02, 0.0]))
    toward, away = volume_irradiance(c, np.array([-1.0, 0.0, 0.0])), volume_irradiance(c, np.array([1.0, 0.0, 0.0]))
    assert toward.mean() < 0.9 * away.mean(), (toward, away)


def test_a_directional_light_map_on_an_object_that_moves_is_refused_in_one_line(tmp_path):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "inm-modh6"\norbit_m = 0.1\n')
    assert_one_line_error(arsim("render", path, "-o", tmp_path / "out"), "orbit_m = 0.1")


def test_a_sphere_gets_a_directional_light_map_shadowed_where_it_faces_the_torus(tmp_path):
    """A sphere beside the torus with lighting = inm-modh6: its texels lie on the sphere, and at the
    equator the constant term facing the torus is far below the one facing away (0.56 of it here)."""
    from arsim.render.content import light_objects, scene_objects
    from arsim.scenario import load_scenario

    path = tmp_path / "sphere.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "ibl"\n'
                    '[[render.objects]]\nkind = "sphere"\nposition_m = [0.1, 0.0]\nsize_m = 0.02\nlighting = "inm-modh6"\n'
                    'lightmap_size = 16\n')
    torus, sphere = scene_objects(load_scenario(path).render)
    surface = sphere.lightmap_surface()
    centre = np.array([0.1, 0.02, 0.0])
    np.testing.assert_allclose(np.linalg.norm(surface.points - centre, axis=-1), 0.02, rtol=1e-12)
    _, baked = light_objects([torus, sphere], to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32))
    constant = baked.material.directional_map[..., 0, :].mean(axis=-1)  # (16, 32)
    equator = np.abs(surface.normals[..., 1]) < 0.2
    toward = equator & (surface.normals[..., 0] < -0.9)
    away = equator & (surface.normals[..., 0] > 0.9)
    assert toward.sum() >= 2 and away.sum() >= 2
    assert constant[toward].mean() < 0.8 * constant[away].mean(), (constant[toward].mean(), constant[away].mean())
