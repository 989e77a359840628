"""Directional light maps for meshes read from files: the unwrapped second UV set (one atlas, charts
that do not overlap), the light map's texels on the surface, and an arch's bake (its own occlusion, and
its contact shadow on a disc)."""

import numpy as np
import pytest

from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.render.mesh_lightmap import GUTTER, lightmap_texels, lightmap_unwrap, texel_triangles
from arsim.render.meshes import Mesh, grid_mesh, load_mesh
from tests.conftest import ENVMAPS


def arch_file(path):
    """An arch of three boxes (two pillars and a lintel, 1 x 1 x 0.3), flat-shaded, written to OBJ."""
    import trimesh

    move = trimesh.transformations.translation_matrix
    parts = [trimesh.creation.box([0.2, 0.8, 0.3], transform=move([-0.4, 0.4, 0.0])),
             trimesh.creation.box([0.2, 0.8, 0.3], transform=move([0.4, 0.4, 0.0])),
             trimesh.creation.box([1.0, 0.2, 0.3], transform=move([0.0, 0.9, 0.0]))]
    arch = trimesh.util.concatenate(parts)
    arch.unmerge_vertices()  # (a vertex per face corner: the faces' own normals)
    arch.export(path, include_normals=True)
    return path


def test_a_planar_squares_texels_lie_where_their_uv_says():
    """A 0.2 m square in the table plane with planar UVs: every texel covered, at the point its centre's
    (u, v) names, normal +y."""
    u, v = np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5), indexing="ij")
    points = np.stack([0.2 * u, np.zeros_like(u), -0.2 * v], axis=-1)
    mesh = grid_mesh(points, np.broadcast_to([0.0, 1.0, 0.0], points.shape), np.broadcast_to([1.0, 0.0, 0.0], points.shape),
                     np.stack([u, v], axis=-1))
    surface = lightmap_texels(mesh, np.eye(4), (8, 16))
    assert surface.valid.all()
    centre_u = (np.arange(16) + 0.5) / 16
    centre_v = 1.0 - (np.arange(8) + 0.5) / 8
    np.testing.assert_allclose(surface.points[..., 0], np.broadcast_to(0.2 * centre_u, (8, 16)), atol=1e-7)
    np.testing.assert_allclose(surface.points[..., 2], np.broadcast_to(-0.2 * centre_v[:, None], (8, 16)), atol=1e-7)
    np.testing.assert_allclose(surface.normals, np.broadcast_to([0.0, 1.0, 0.0], (8, 16, 3)), atol=1e-7)


def test_the_unwrapped_charts_are_one_atlas_without_overlap(tmp_path):
    """The arch's second UV set: inside [0, 1], one atlas, no texel centre inside two triangles, and every
    triangle with a texel's area gets texels; the first UV set and the surface are kept."""
    mesh, _ = load_mesh(arch_file(tmp_path / "arch.obj"))
    unwrapped, (h, w) = lightmap_unwrap(mesh, 32)
    assert max(h, w) <= 32 and (unwrapped.uvs2 >= 0).all() and (unwrapped.uvs2 <= 1).all()
    assert len(unwrapped.indices) == len(mesh.indices)
    area = lambda m: np.linalg.norm(np.cross(*(m.positions[m.indices[:, k]] - m.positions[m.indices[:, 0]] for k in (1, 2))), axis=1)
    np.testing.assert_allclose(area(unwrapped).sum(), area(mesh).sum(), rtol=1e-6)
    # texel centres inside each triangle (barycentric), counted over all triangles
    centres = np.stack(np.meshgrid((np.arange(w) + 0.5) / w, 1.0 - (np.arange(h) + 0.5) / h), axis=-1).reshape(-1, 2)
    tri = unwrapped.uvs2[unwrapped.indices].astype(np.float64)  # (T, 3, 2)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    d = centres[:, None, :] - tri[None, :, 0]
    l1 = (d[..., 0] * e2[:, 1] - d[..., 1] * e2[:, 0]) / det
    l2 = (e1[:, 0] * d[..., 1] - e1[:, 1] * d[..., 0]) / det
    inside = (l1 > 1e-6) & (l2 > 1e-6) & (l1 + l2 < 1 - 1e-6)
    assert inside.sum(axis=1).max() == 1
    ids = texel_triangles(unwrapped.uvs2, unwrapped.indices, (h, w))
    uv_area = 0.5 * np.abs(det) * h * w
    assert set(np.flatnonzero(uv_area > 2.0)) <= set(np.unique(ids[ids >= 0]))


@pytest.fixture(scope="module")
def arch_scene(tmp_path_factory):
    from arsim.render.content import light_objects, scene_objects
    from arsim.scenario import load_scenario

    folder = tmp_path_factory.mktemp("arch")
    arch_file(folder / "arch.obj")
    (folder / "arch.toml").write_text('[[render.objects]]\nkind = "mesh"\nmesh = "arch.obj"\nsize_m = 0.1\n'
                                      'lighting = "inm-modh6"\nlightmap_size = 32\n'
                                      '[[render.objects]]\nkind = "disc"\nsize_m = 0.1\nlighting = "inm-h4"\nlightmap_size = 24\n')
    objects = scene_objects(load_scenario(folder / "arch.toml").render)
    return objects, light_objects(objects, to_layout(read_hdr(ENVMAPS[1]), "anglemap", 32))


def test_an_arch_gets_a_directional_light_map_with_its_own_occlusion(arch_scene):
    """The arch (0.1 m wide): a texel under the lintel and one on top of it, their normals' irradiance
    (the constant term of modh6 at the normal): the top sees the whole sky, under the lintel the pillars
    and the lintel hide most of it; every texel with a triangle is baked, and lit unless its face is pressed against another."""
    (arch, _), (baked, _) = arch_scene
    surface = arch.lightmap_surface()
    coefficients = baked.material.directional_map
    assert coefficients.shape[:2] == surface.valid.shape and coefficients.shape[2:] == (6, 3)
    assert surface.valid.mean() > 0.4
    constant = coefficients[..., 0, :].mean(axis=-1)
    top = surface.valid & (surface.normals[..., 1] > 0.99) & (surface.points[..., 1] > 0.099)
    under = surface.valid & (surface.normals[..., 1] < -0.99) & (surface.points[..., 1] > 0.07)
    assert top.sum() > 10 and under.sum() > 10
    assert constant[under].mean() < 0.5 * constant[top].mean(), (constant[under].mean(), constant[top].mean())
    # no light where a face is pressed against another: the pillars' feet on the table, their tops against the
    # lintel's underside (and it against them); everywhere else some
    x, y, vertical = surface.points[..., 0], surface.points[..., 1], np.abs(surface.normals[..., 1]) > 0.99
    pressed = surface.valid & vertical & ((y < 1e-6) | ((np.abs(y - 0.08) < 1e-6) & (np.abs(x) > 0.03 - 1e-6)))
    inside = pressed & (np.abs(np.abs(x) - 0.04) < 0.0099) & (np.abs(surface.points[..., 2]) < 0.0149)  # (not on an edge)
    assert inside.sum() >= 4 and (constant[inside] == 0).all()
    assert (constant[surface.valid & ~pressed] > 0).all() and (coefficients[~surface.valid] == 0).all()


def test_an_arch_casts_its_contact_shadow_on_the_disc(arch_scene):
    """The disc under the arch (pillars at |x| 0.03 to 0.05, |z| < 0.015): nothing under the pillars' feet,
    and beside a pillar's inner face far less light than at the same x out in the open (z = 0.06)."""
    _, (_, disc) = arch_scene
    constant = disc.material.directional_map[..., 0, :].mean(axis=-1)
    centres = ((np.arange(24) + 0.5) / 24 * 2 - 1) * 0.1
    z, x = np.meshgrid(centres, centres, indexing="ij")  # row 0 at z = -0.1 (v = 1)
    assert (constant[(np.abs(np.abs(x) - 0.04) < 0.009) & (np.abs(z) < 0.014)] == 0).all()
    beside = (np.abs(np.abs(x) - 0.025) < 0.005) & (np.abs(z) < 0.014)
    open_ = (np.abs(np.abs(x) - 0.025) < 0.005) & (np.abs(z - 0.06) < 0.014)
    assert beside.sum() >= 4 and open_.sum() >= 4
    assert constant[beside].mean() < 0.7 * constant[open_].mean(), (constant[beside].mean(), constant[open_].mean())


def test_a_mesh_without_directional_lighting_keeps_its_file_uvs(tmp_path):
    from arsim.render.content import scene_objects
    from arsim.scenario import load_scenario

    arch_file(tmp_path / "arch.obj")
    (tmp_path / "s.toml").write_text('[[render.objects]]\nkind = "mesh"\nmesh = "arch.obj"\nlighting = "ibl"\n')
    (obj,) = scene_objects(load_scenario(tmp_path / "s.toml").render)
    mesh, _ = load_mesh(tmp_path / "arch.obj")
    assert isinstance(obj.mesh, Mesh) and len(obj.mesh.positions) == len(mesh.positions) and obj.lightmap_surface is None
    assert GUTTER >= 1


def test_a_light_map_too_small_for_the_meshs_charts_is_refused_in_one_line(tmp_path):
    """200 separate triangles cannot be packed into 4 x 4 texels with gutters between them."""
    import trimesh

    from tests.test_cli import arsim, assert_one_line_error

    corners = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    offsets = np.stack(np.meshgrid(np.arange(20), np.arange(10), indexing="ij"), -1).reshape(-1, 2) * 0.02
    vertices = (corners[None] + np.pad(offsets, ((0, 0), (0, 1)))[:, None, [0, 2, 1]]).reshape(-1, 3)
    trimesh.Trimesh(vertices, np.arange(len(vertices)).reshape(-1, 3), process=False).export(tmp_path / "bits.obj")
    (tmp_path / "s.toml").write_text('[[render.objects]]\nkind = "mesh"\nmesh = "bits.obj"\nlighting = "inm-h4"\nlightmap_size = 4\n')
    assert_one_line_error(arsim("render", tmp_path / "s.toml", "-o", tmp_path / "out"), "give a larger lightmap_size")
