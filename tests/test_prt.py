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
from tests.test_render import CAMERA, EYE, KD, bumps, look_at  # noqa: F401  (fixtures below)
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


@pytest.mark.parametrize("variant", prt.VARIANTS)
def test_gl_per_vertex_prt_equals_the_numpy_reference(gl, maps, variant):  # noqa: F811
    """Per-vertex PRT on a normal-mapped sphere (diffuse only): matrices linear in the vertex's world point,
    so that GL's interpolated coefficients are the same function at the fragment's point (debug target);
    GL against prt_diffuse within 1e-3 relative."""
    from tests.test_render import render

    rng = np.random.default_rng(11)
    v = prt.get_variant(variant)
    mesh = uv_sphere(0.1)
    positions = mesh.positions.astype(np.float64) + [0.0, 0.1, 0.0]
    matrices, at = linear_in_position(v, positions, rng)
    light = np.zeros((9, 3))
    light[0] = [3.0, 2.5, 2.0]
    light[1:] = rng.uniform(-0.2, 0.2, (8, 3))
    material = Material(KD, (0.0, 0.0, 0.0), 80.0, normal_map=bumps(), prt_variant=variant, prt_matrices=matrices)
    r = render(gl, maps, material, debug=True)
    r.relight(light)
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    hdr, mask = r.read_hdr(), r.read_mask() > 0.5
    normal, point = (x[..., :3].astype(np.float64) for x in r.read_debug())
    assert 0.03 < mask.mean() < 0.5
    coefficients = at(point[mask]) @ light
    reference = np.array(KD) * prt.prt_diffuse(coefficients, v, normal[mask])
    rel = np.abs(hdr[mask] - reference) / np.abs(reference)
    assert rel.max() < 1e-3, rel.max()  # (RGBA16F, as the renderer's other GL tests)


@pytest.mark.parametrize("variant", ["gs", "sep"])
def test_gl_per_texel_prt_equals_the_numpy_reference(gl, maps, variant):  # noqa: F811
    """Per-texel PRT: the coefficients relit into the light-map texture, looked up as GL does (bilinear,
    repeating, level 0 at this distance)."""
    from arsim.evaluate.inm_compare import sample_periodic
    from tests.test_render import render

    rng = np.random.default_rng(12)
    v = prt.get_variant(variant)
    matrices = rng.uniform(-0.2, 0.2, (16, 32, v.count, 9)).astype(np.float32)
    matrices[..., 0, 0] += 2.0
    light = np.zeros((9, 3))
    light[0] = [3.0, 2.5, 2.0]
    light[1:] = rng.uniform(-0.1, 0.1, (8, 3))
    material = Material(KD, (0.0, 0.0, 0.0), 80.0, normal_map=bumps(), prt_variant=variant, prt_matrices=matrices)
    r = render(gl, maps, material, debug=True)
    r.relight(light)
    r.render_objects(*look_at(EYE, [0.0, 0.1, 0.0]))
    hdr, mask = r.read_hdr(), r.read_mask() > 0.5
    normal, incident = (x.astype(np.float64) for x in r.read_debug())
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
