"""Precomputed radiance transfer (arsim/lighting/prt.py): SH of any order and their rotations, the
transfer against direct sums over the environment (unshadowed: the irradiance map; under the arch: a
Monte Carlo sum of the visible light), the light turned against the scene turned back, the variants'
GL path against their NumPy reference, and bad input."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.core.errors import ArsimError
from arsim.lighting import prt
from arsim.lighting.bases.functions import sh9
from arsim.render.meshes import uv_sphere
from arsim.render.renderer import Material
from tests.test_render import EYE, KD, bumps, look_at
from tests.test_render import gl, maps  # noqa: F401


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_sh_of_any_order_extend_the_quadratic_sh_and_rotate_exactly():
    rng = np.random.default_rng(0)
    d = unit(rng.normal(size=(200, 3)))
    np.testing.assert_allclose(prt.sh_basis(d, 3), sh9(d), atol=1e-12)
    r = Rotation.random(random_state=3).as_matrix()
    rotation = prt.sh_rotation(r, 6)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(36), atol=1e-12)
    light = rng.normal(size=36)
    # the light turned by R: L'(w) = L(R^T w)
    np.testing.assert_allclose(prt.sh_basis(d, 6) @ (rotation @ light), prt.sh_basis(d @ r, 6) @ light, atol=1e-12)


def test_the_separable_maps_are_inverse_and_the_separable_basis_is_the_truncated_svd():
    rng = np.random.default_rng(1)
    s = rng.random((500, 2))
    np.testing.assert_allclose(prt.hemisphere_to_square(prt.square_to_hemisphere(s)), s, atol=1e-12)
    d = prt.square_to_hemisphere(s)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    assert (d[:, 2] >= 0).all()
    # exit radiance of random incident quadratic SH through the separable basis against the gold standard:
    # all nine singular values give it back (but for the 64 x 64 table's resampling); four leave what the
    # dropped ones held, less when C is absorbed into A (the spec's suggestion)
    n = unit(np.concatenate([rng.normal(size=(2000, 2)) * 0.7, np.ones((2000, 1))], axis=1))
    gs = prt.get_variant("gs")
    c = rng.normal(size=(9, 40)) * 0.3
    c[0] = 2.0
    exact = gs.evaluate(n) @ (gs.projection @ c)

    def error(absorbed, terms):
        sep = prt.separable(absorbed, terms)
        return np.sqrt(np.mean((sep.evaluate(n) @ (sep.projection @ c) - exact) ** 2) / np.mean(exact ** 2))

    assert error(False, 9) < 2e-3 and error(True, 9) < 2e-3
    assert error(True, 4) < error(False, 4) < 0.1


def linear_in_position(variant, positions, rng):
    """Per-vertex matrices (V, count, 9) of a variant whose incident radiance's SH (9 x 9 per point, the
    constant term dominant, so that every variant's exit radiance stays well above 0, where a relative
    error means something) is a linear function of the vertex's world point; and that function."""
    a = rng.uniform(-0.05, 0.05, (9, 9))
    b = rng.uniform(-0.3, 0.3, (3, 9, 9))
    a[0, 0] += 1.0

    def at(p):
        return variant.projection @ (a + np.einsum("...i,ikl->...kl", p, b))

    return at(positions).astype(np.float32), at


def quadratic_light(rng, spread):
    """SH bands 0-2 (9, 3) of a light: a constant and small others."""
    light = np.zeros((9, 3))
    light[0] = [3.0, 2.5, 2.0]
    light[1:] = rng.uniform(-spread, spread, (8, 3))
    return light


def relit_render(gl, maps, variant, matrices, light):  # noqa: F811
    """The normal-mapped sphere with PRT (diffuse only), relit and drawn: HDR, mask, debug targets (float64)."""
    from tests.test_render import render

    material = Material(KD, KS0, 80.0, normal_map=bumps(), prt_variant=variant, prt_matrices=matrices)
    r = render(gl, maps, material, debug=True)
    r.relight(light)
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    mask = r.read_mask() > 0.5
    assert 0.03 < mask.mean() < 0.5
    return r.read_hdr(), mask, [x.astype(np.float64) for x in r.read_debug()]


@pytest.mark.parametrize("variant", prt.VARIANTS)
def test_gl_per_vertex_prt_equals_the_numpy_reference(gl, maps, variant):  # noqa: F811
    """Per-vertex PRT on a normal-mapped sphere (diffuse only): matrices linear in the vertex's world point,
    so that GL's interpolated coefficients are the same function at the fragment's point (debug target);
    GL against prt_diffuse within 1e-3 relative."""
    rng = np.random.default_rng(11)
    v = prt.get_variant(variant)
    mesh = uv_sphere(0.1)
    positions = mesh.positions.astype(np.float64) + [0.0, 0.1, 0.0]
    matrices, at = linear_in_position(v, positions, rng)
    light = quadratic_light(rng, 0.2)
    hdr, mask, (normal, point) = relit_render(gl, maps, variant, matrices, light)
    normal, point = normal[..., :3], point[..., :3]
    coefficients = at(point[mask]) @ light
    reference = np.array(KD) * prt.prt_diffuse(coefficients, v, normal[mask])
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3, rel.max()  # (RGBA16F, as the renderer's other GL tests)


@pytest.mark.parametrize("variant", prt.VARIANTS)
def test_gl_per_texel_prt_equals_the_numpy_reference(gl, maps, variant):  # noqa: F811
    """Per-texel PRT: the coefficients relit into the light-map texture, looked up as GL does (bilinear,
    repeating, level 0 at this distance)."""
    from arsim.evaluate.inm_compare import sample_periodic

    rng = np.random.default_rng(12)
    v = prt.get_variant(variant)
    incident = rng.uniform(-0.05, 0.05, (16, 32, 9, 9))  # per texel, the incident radiance's SH: a constant
    incident[..., 0, 0] += 1.0  # dominates, so that every variant's exit radiance stays well above 0
    matrices = np.einsum("bs,hwsl->hwbl", v.projection, incident).astype(np.float32)
    light = quadratic_light(rng, 0.1)
    hdr, mask, (normal, incident) = relit_render(gl, maps, variant, matrices, light)
    uv2 = np.stack([normal[mask][:, 3], incident[mask][:, 3]], axis=-1)
    coefficients = sample_periodic(prt.relight(matrices.reshape(-1, v.count, 9), light).reshape(16, 32, v.count, 3), uv2)
    reference = np.array(KD) * prt.prt_diffuse(coefficients, v, normal[mask][:, :3])
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3, rel.max()


def test_bad_prt_input_is_refused_in_one_line(gl, maps):  # noqa: F811
    from tests.test_render import render

    with pytest.raises(ArsimError, match="unknown PRT variant 'nope'"):
        prt.get_variant("nope")
    for order in (2, 0, 11):
        with pytest.raises(ArsimError, match=f"PRT order {order}: give 3 to 10"):
            prt.check_order(order)
    with pytest.raises(ArsimError, match="prt-gs material holds"):
        render(gl, maps, Material(KD, KS0, 80.0, prt_variant="gs", prt_matrices=np.zeros((10, 4, 9))))
    with pytest.raises(ArsimError, match="the PRT transfer has 10 vertices"):
        render(gl, maps, Material(KD, KS0, 80.0, prt_variant="gs", prt_matrices=np.zeros((10, 9, 9))))


KS0 = (0.0, 0.0, 0.0)


def environment(size=32):
    from arsim.core.hdr_io import read_hdr
    from arsim.core.resample import to_layout
    from tests.conftest import ENVMAPS

    return to_layout(read_hdr(ENVMAPS[1]), "anglemap", size)


def test_unshadowed_transfer_is_the_irradiance_map_within_the_sh_truncation():
    """Unshadowed PRT of order 5 against the irradiance map (the accurate map, E / pi over its normaliser,
    at its own texels' normals, every 7th texel of a 32 x 32 map): the difference stays under the bound the
    clamped cosine's dropped bands allow, sum over l >= 5 of |A_l| |L_l| sqrt((2l + 1) / 4 pi), with the
    environment's bands up to 31 from its texels."""
    from numpy.polynomial.legendre import leggauss
    from scipy.special import eval_legendre

    from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
    from arsim.lighting.accurate import accurate_maps
    from arsim.lighting.bases.lightmap import probe_samples
    from arsim.render.content import tangent_frames

    env = environment(32)
    order = 5
    inside = anglemap_disk_mask(32)
    normals = anglemap_directions(32)[inside][::7]
    tangents, _ = tangent_frames(normals)
    transfer = prt.compute_transfer(np.zeros_like(normals), normals, tangents, order, None, samples=8192)
    e_prt = transfer.unshadowed @ prt.light_sh(env, order)
    directions, weighted = probe_samples(env)
    solid = probe_samples(np.ones_like(env))[1][:, 0]
    normaliser = np.maximum(normals @ directions.T, 0.0) @ solid
    e_map = accurate_maps(env, [1.0])[0][inside][::7] * normaliser[:, None]
    x, w = leggauss(200)
    x, w = (x + 1) / 2, w / 2
    bands = prt.sh_basis(directions, 32).T @ weighted
    bound = np.zeros(3)
    for l in range(order, 32):
        a_l = 2 * np.pi * np.sum(w * x * eval_legendre(l, x))
        bound += abs(a_l) * np.linalg.norm(bands[l * l:(l + 1) ** 2], axis=0) * np.sqrt((2 * l + 1) / (4 * np.pi))
    error = np.abs(e_prt - e_map).max(axis=0)
    assert (error <= bound).all(), (error, bound)
    assert (error > 0.05 * bound).all()  # (the truncation is there to see: not a thing compared with itself)


ARCH = __import__("pathlib").Path(__file__).resolve().parents[1] / "assets" / "meshes" / "arch.obj"


def arch_scene(model_turn=None):
    """The arch (0.1 m wide, 0.1 high, 0.03 deep) standing over the origin, lit by PRT; optionally turned
    about the vertical through the origin. Returns the object and the scene's blocked() rays."""
    import dataclasses

    from arsim.render.content import scene_objects, scene_occlusion
    from arsim.scenario.sections import RenderObjectSection, RenderSection

    (arch,) = scene_objects(RenderSection(objects=(RenderObjectSection("mesh", mesh=ARCH, size_m=0.1, lighting="prt-gs"),)))
    if model_turn is not None:
        turn = np.eye(4)
        turn[:3, :3] = model_turn
        arch = dataclasses.replace(arch, model=turn @ arch.model)
    return arch, scene_occlusion([arch], [False]).blocked


def band_limited_light(order, seed):
    """SH (order^2, 3) of a light positive everywhere: a constant and small higher bands."""
    rng = np.random.default_rng(seed)
    light = rng.uniform(-0.08, 0.08, (order * order, 3))
    light[0] = [1.0, 0.9, 0.8]
    d = unit(rng.normal(size=(20000, 3)))
    assert (prt.sh_basis(d, order) @ light > 0).all()
    return light


def test_a_point_under_the_arch_receives_what_the_visibility_lets_through():
    """The shadowed transfer at a point of the table under the arch's lintel, relit by a band-limited light
    (so that PRT's order-5 product is the integral itself), against a direct Monte Carlo sum of the light
    over cosine-weighted rays cast against the arch and the table: within 2 %; and the arch takes away a
    third of the light (the test is of shadows, not of an open sky)."""
    _, blocked = arch_scene()
    order = 5
    light = band_limited_light(order, 5)
    point, normal, tangent = np.array([[0.0, 1e-4, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    transfer = prt.compute_transfer(point, normal, tangent, order, blocked, samples=8192)
    e_prt = (transfer.shadowed @ light)[0]
    rng = np.random.default_rng(9)
    xi = rng.random((40000, 2))
    r, phi = np.sqrt(xi[:, 0]), 2 * np.pi * xi[:, 1]
    rays = np.stack([r * np.cos(phi), np.sqrt(1 - xi[:, 0]), r * np.sin(phi)], axis=-1)  # cosine-weighted about +y
    visible = ~blocked(point, rays[:, None, :])[:, 0]
    e_mc = np.pi * np.mean(visible[:, None] * (prt.sh_basis(rays, order) @ light), axis=0)
    assert (np.abs(e_prt - e_mc) / e_mc < 0.02).all(), (e_prt, e_mc)
    open_sky = (transfer.unshadowed @ light)[0]
    assert (e_prt < 0.75 * open_sky).all() and (e_prt > 0.05 * open_sky).all(), e_prt / open_sky  # (0.63 to 0.69)


def test_turning_the_light_is_turning_the_scene_the_other_way():
    """The arch's per-vertex transfer relit by the light turned by alpha about the vertical (SH rotation)
    equals the transfer computed with the arch turned by -alpha relit by the light as it was: the same
    incident radiance at every vertex, in each vertex's own frame (alpha a multiple of the rule's
    azimuth step, so that both sample the same directions relative to the arch: equal to rounding)."""
    from scipy.spatial.transform import Rotation

    from arsim.render.transfer import vertex_frames

    order, samples = 5, 2048
    n_phi = 2 * int(round(np.sqrt(samples / 2)))
    alpha = 5 * 2 * np.pi / n_phi
    turn = Rotation.from_rotvec([0.0, alpha, 0.0]).as_matrix()
    light = band_limited_light(order, 6)
    arch, blocked = arch_scene()
    turned, blocked_turned = arch_scene(turn.T)
    lit = prt.compute_transfer(*vertex_frames(arch.mesh, arch.model), order, blocked, samples).relight(prt.sh_rotation(turn, order) @ light)
    back = prt.compute_transfer(*vertex_frames(turned.mesh, turned.model), order, blocked_turned, samples).relight(light)
    assert np.abs(lit).max() > 0.1
    np.testing.assert_allclose(lit, back, atol=1e-5 * np.abs(lit).max())


def test_the_sh_projection_table_has_its_interface_shape_and_the_exact_fits():
    from arsim.evaluate.prt_compare import sh_projection

    table = sh_projection()
    assert table["functions"] == ["Y00", "Y1-1", "Y10", "Y11", "Y2-2", "Y2-1", "Y20", "Y21", "Y22"]
    assert list(table["mse"]) == ["hl2", "sal4", "sal9", "h4", "h6", "sep4"]
    assert all(len(v) == 9 and all(0 <= e <= 0.5 + 1e-9 for e in v) for v in table["mse"].values())
    mse = table["mse"]
    # what each span holds exactly: H4 = {1, x, y, z}, H6 adds xy and x^2 - y^2, HSH holds the constant
    # and, shifted, z; HL2 (three linear functions, no constant) holds x, y, z but not 1
    assert max(mse["h4"][:4]) < 1e-20 and max(mse["h6"][:5] + [mse["h6"][8]]) < 1e-20
    assert mse["sal4"][0] < 1e-20 and mse["sal4"][2] < 1e-20 and mse["sal9"][6] < 1e-20
    assert max(mse["hl2"][1:4]) < 1e-20 and mse["hl2"][0] > 0.1
    # a function odd in both x and y (xy) or of the form x^2 - y^2 is out of reach of every basis of <= 4
    for key in ("hl2", "sal4", "h4", "sep4"):
        assert abs(mse[key][4] - 0.5) < 1e-9 and abs(mse[key][8] - 0.5) < 1e-9


def test_prt_compare_writes_its_tables_and_images(tmp_path):
    import json

    from tests.test_cli import arsim

    env = __import__("pathlib").Path(__file__).resolve().parents[1] / "assets" / "envmaps" / "city.exr"
    r = arsim("prt", "compare", "-o", tmp_path / "prt", "--env", env, "--samples", "128", "--variants", "gs,hl2")
    assert r.returncode == 0, r.stderr
    scores = json.loads((tmp_path / "prt" / "prt_compare.json").read_text())["scores"]["city"]
    assert set(scores) == {"prt", "gs", "hl2"}
    # the normal map's detail: the gold standard is nearer the reference than PRT without it, and than HL2
    assert scores["gs"]["mse"] < scores["prt"]["mse"] and scores["gs"]["mse"] < scores["hl2"]["mse"]
    for name in ("prt_compare.md", "variants.png", "sh_projection.json", "sh_projection.md"):
        assert (tmp_path / "prt" / name).stat().st_size > 100


@pytest.mark.parametrize("args, fragment", [
    (["--variants", "gs,nope"], "unknown PRT variant 'nope'"),
    (["--order", "2"], "PRT order 2: give 3 to 10"),
    (["--samples", "100000"], "at most 65536"),
])
def test_prt_compare_refuses_bad_options_in_one_line(tmp_path, args, fragment):
    from tests.test_cli import arsim, assert_one_line_error

    assert_one_line_error(arsim("prt", "compare", "-o", tmp_path / "out", *args), fragment)
    assert not (tmp_path / "out").exists()


def test_a_scenario_with_a_bad_prt_order_is_refused_in_one_line(tmp_path):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text('[[render.objects]]\nkind = "torus"\nlighting = "prt-gs"\nprt_order = 2\n')
    assert_one_line_error(arsim("validate", path), "prt_order")


def test_prt_per_texel_without_a_light_map_uv_set_is_refused():
    """A mesh object made without a light-map unwrap (no second UV set) asked for its transfer per texel."""
    from arsim.render.renderer import SceneObject
    from arsim.render.transfer import PrtSettings, object_transfer

    obj = SceneObject(uv_sphere(0.05, 8, 16), Material(KD, KS0, 80.0))
    with pytest.raises(ArsimError, match="PRT per texel needs the object's light-map UV set"):
        object_transfer(obj, PrtSettings("gs", per_texel=True), None)


def test_gl_cpca_summed_per_vertex_equals_the_uncompressed_matrices_it_stands_for(gl, maps):  # noqa: F811
    """CPCA per vertex: the GPU sums the clusters' coefficients with each vertex's weights; the image equals
    (within 1e-3 relative) the one drawn from the matrices the compression stands for, uncompressed."""
    import dataclasses

    from tests.test_render import render

    rng = np.random.default_rng(13)
    v = prt.get_variant("sep-c")
    mesh = uv_sphere(0.1)
    matrices, _ = linear_in_position(v, mesh.positions.astype(np.float64) + [0.0, 0.1, 0.0], rng)
    compressed = prt.compress(matrices, clusters=8, vectors=2)
    assert np.abs(compressed.matrices() - matrices).max() > 1e-4  # (lossy: the test is of the sum, not of a copy)
    light = np.zeros((9, 3))
    light[0] = [3.0, 2.5, 2.0]
    light[1:] = rng.uniform(-0.2, 0.2, (8, 3))
    material = Material(KD, KS0, 80.0, normal_map=bumps(), prt_variant="sep-c", prt_matrices=matrices,
                        prt_compressed=compressed, prt_light=light)
    images = []
    for m in (material, dataclasses.replace(material, prt_matrices=compressed.matrices().astype(np.float32), prt_compressed=None)):
        r = render(gl, maps, m)
        images.append((r.read_hdr(), r.read_mask() > 0.5))
    (a, mask), (b, _) = images
    assert 0.03 < mask.mean() < 0.5
    rel = np.abs(a[mask] - b[mask]) / np.abs(b[mask])
    assert rel.max() < 1e-3, rel.max()


def test_the_render_loop_relights_prt_objects_as_the_probe_grows(gl, maps):  # noqa: F811
    """A FrameLoop replaying three lights over six frames: the step "relight" runs in frames 0, 2 and 4 only
    (and the profile's trace shows it), and the object's coefficients are then the last light's (read back
    from the GPU's buffer)."""
    from arsim.render.loop import FrameLoop
    from arsim.render.renderer import Renderer, SceneObject
    from arsim.tracking.apriltag import TagPose
    from tests.test_render import CAMERA

    rng = np.random.default_rng(14)
    mesh = uv_sphere(0.05, 6, 12)
    matrices = rng.uniform(0.0, 1.0, (len(mesh.positions), 9, 9)).astype(np.float32)
    renderer = Renderer(CAMERA, maps, gl)
    renderer.add(SceneObject(mesh, Material(KD, KS0, 80.0, prt_variant="gs", prt_matrices=matrices)))
    lights = [environment(16) * s for s in (0.2, 0.6, 1.0)]
    lost = TagPose(None, None, None)
    loop = FrameLoop(gl, None, renderer, pose_cache={k: lost for k in range(6)}, lights=lights, light_frames=6)
    frame = np.zeros((CAMERA.height, CAMERA.width, 3), np.uint8)
    records = [loop.run(frame, k)[1] for k in range(6)]
    assert ["relight" in r.cpu_ms for r in records] == [True, False, True, False, True, False]
    from arsim.evaluate.profile import ProfileRun  # the profile's trace has the step on a track of its own

    events = [e for e in ProfileRun("t", "accurate", 33.3, records).trace()["traceEvents"] if e.get("name") == "relight"]
    assert len(events) == 3
    buffer = renderer.objects[0].prt[1]
    got = np.frombuffer(buffer.read(), np.float32).reshape(len(mesh.positions), 9, 3)
    np.testing.assert_allclose(got, prt.relight(matrices, prt.light_sh(lights[-1], 3)), rtol=1e-5, atol=1e-6)


def test_a_growing_probe_is_refused_with_a_light_given_whole(tmp_path):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "grow.toml"
    path.write_text('[render]\nprt_light = "growing"\n[[render.objects]]\nkind = "torus"\nlighting = "prt-gs"\n')
    env = __import__("pathlib").Path(__file__).resolve().parents[1] / "assets" / "envmaps" / "city.exr"
    assert_one_line_error(arsim("render", path, "-o", tmp_path / "out", "--env", env), 'prt_light = "growing"')
    assert not (tmp_path / "out").exists()


def test_one_bounce_under_the_arch_adds_what_a_two_level_monte_carlo_sum_says():
    """prt_bounces = 1 at the point of the table under the arch: what the bounce adds to the shadowed
    transfer (relit by a band-limited light) against an independent estimate: cosine-weighted rays from the
    point, and at each hit on the arch the direct light there, by cosine-weighted rays about the hit face's
    normal (albedo / pi of it sent back). Within 15 % of the bounce (the transfer takes the light the arch
    sends from the nearest of its area samples); and the bounce is a visible share of the light."""
    import trimesh

    from arsim.render.content import scene_occlusion
    from arsim.render.transfer import bounce_gather

    arch, _ = arch_scene()
    occlusion = scene_occlusion([arch], [False])
    order, light = 5, band_limited_light(5, 7)
    point, normal, tangent = np.array([[0.0, 1e-4, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    albedo = float(np.mean(arch.material.kd))
    direct = prt.compute_transfer(point, normal, tangent, order, occlusion.blocked, samples=4096)
    bounced = prt.compute_transfer(point, normal, tangent, order, samples=4096, distance=occlusion.distance,
                                   bounce=bounce_gather(occlusion, order, 0.2))
    added = ((bounced.shadowed - direct.shadowed) @ light)[0]

    rng = np.random.default_rng(21)

    def cosine_rays(n, count):
        xi = rng.random((count, 2))
        r, phi = np.sqrt(xi[:, 0]), 2 * np.pi * xi[:, 1]
        t = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        return (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * np.cross(n, t) + np.sqrt(1 - xi[:, :1]) * n

    positions = arch.mesh.positions.astype(np.float64) @ arch.model[:3, :3].T + arch.model[:3, 3]
    mesh = trimesh.Trimesh(positions, arch.mesh.indices, process=False)
    rays = cosine_rays(np.array([0.0, 1.0, 0.0]), 3000)
    where, index, faces = mesh.ray.intersects_location(np.repeat(point, len(rays), axis=0) + 1e-6, rays, multiple_hits=False)
    sent = np.zeros(3)
    for q, face in zip(where, faces):
        n_q = mesh.face_normals[face]
        out = cosine_rays(n_q, 200)
        seen = ~occlusion.blocked(q[None] + n_q * 1e-5, out[:, None, :])[:, 0]
        sent += albedo * np.mean(seen[:, None] * (prt.sh_basis(out, order) @ light), axis=0)  # albedo / pi x E_q
    estimate = np.pi * sent / len(rays)
    assert (np.abs(added - estimate) < 0.15 * estimate).all(), (added, estimate)
    assert (added > 0.02 * (direct.shadowed @ light)[0]).all()


def test_transfers_are_kept_in_the_cache_folder_and_not_at_all_when_it_is_off(tmp_path, monkeypatch):
    from arsim.lighting.prt import Transfer, cached_transfer

    calls = []

    def compute():
        calls.append(1)
        return Transfer(np.ones((2, 9, 4), np.float32), np.ones((2, 4), np.float32), np.ones((2, 4), np.float32), 2)

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ARSIM_CACHE", "off")
    cached_transfer("k", compute)
    cached_transfer("k", compute)
    assert len(calls) == 2 and list(tmp_path.iterdir()) == []  # (no folder named "off", nothing kept)
    monkeypatch.setenv("ARSIM_CACHE", str(tmp_path / "cache"))
    first = cached_transfer("k", compute)
    again = cached_transfer("k", compute)
    assert len(calls) == 3 and (tmp_path / "cache" / "prt" / "k.npz").is_file()
    np.testing.assert_array_equal(first.matrices, again.matrices)
