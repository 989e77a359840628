"""Irradiance normal mapping's bases: orthonormality over the hemisphere (the modified H-basis's stated
non-orthogonality), the specs' closed-form projections from SH against the same computed by integration,
projection and reconstruction, `arsim bases compare` end to end, and bad input refused in one line."""

import json
from math import pi, sqrt

import numpy as np
import pytest
from scipy.special import sph_harm_y

from arsim.core.errors import ArsimError
from arsim.evaluate.compare_bases import compare_bases, parse_entries, random_signal, signal_irradiance
from arsim.lighting.bases import BASES, get_basis, gram, parse_basis, project, reconstruct
from arsim.lighting.bases.functions import sh9
from arsim.lighting.bases.irradiance import irradiance
from arsim.lighting.bases.projection import closed_form_checks
from arsim.lighting.bases.quadrature import hemisphere_quadrature, sphere_quadrature
from tests.test_cli import arsim, assert_one_line_error


@pytest.mark.parametrize("name", [n for n, b in BASES.items() if b.orthonormal])
def test_orthonormal_bases_have_an_identity_gram_matrix_over_the_hemisphere(name):
    basis = get_basis(name)
    for count in basis.counts:
        np.testing.assert_allclose(gram(basis, count), np.eye(count), atol=1e-6)


def test_the_modified_h_basis_is_not_orthogonal_as_stated():
    g = gram(get_basis("modh"), 6)
    expected = np.eye(6)
    expected[0, 2] = expected[2, 0] = sqrt(3) / 2  # H1 . H3mod; everything else as the H-basis
    np.testing.assert_allclose(g, expected, atol=1e-6)
    # and H3mod vanishes for the unperturbed normal: H1 alone is the light map
    values = get_basis("modh").evaluate(np.array([0.0, 0.0, 1.0]), 6)
    np.testing.assert_allclose(values[1:], 0.0, atol=1e-15)


def test_sh_is_orthonormal_over_the_sphere_and_equals_scipys_real_harmonics():
    d, w = sphere_quadrature()
    y = sh9(d)
    np.testing.assert_allclose((y * w[:, None]).T @ y, np.eye(9), atol=1e-10)
    theta, phi = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    k = 0
    for l in range(3):
        for m in range(-l, l + 1):
            # real SH from the complex ones, with scipy's Condon-Shortley phase taken out
            c = sph_harm_y(l, abs(m), theta, phi) * (-1) ** abs(m)
            real = c.real if m == 0 else sqrt(2) * (c.real if m > 0 else c.imag)
            np.testing.assert_allclose(y[:, k], real, atol=1e-12)
            k += 1


def test_the_specs_closed_form_projections_from_sh_match_the_integrals():
    for name, (closed, numeric) in closed_form_checks().items():
        assert np.abs(closed - numeric).max() < 1e-3, name


@pytest.mark.parametrize("name", list(BASES))
def test_a_basis_projects_its_own_functions_exactly(name):
    basis = get_basis(name)
    d = np.random.default_rng(1).normal(size=(50, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for count in basis.counts:
        coeffs = np.random.default_rng(2).normal(size=(count, 3))
        q, w = hemisphere_quadrature()
        values = reconstruct(basis, count, coeffs, q)
        np.testing.assert_allclose(project(basis, count, values), coeffs, atol=1e-9)
        np.testing.assert_allclose(reconstruct(basis, count, coeffs, d), basis.evaluate(d, count) @ coeffs)


def test_irradiance_of_a_uniform_sky_is_pi_for_the_normal_and_half_for_grazing():
    d, w = hemisphere_quadrature(96, 192)
    e = irradiance(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), d, w[:, None])
    np.testing.assert_allclose(e[:, 0], [pi, pi / 2], rtol=2e-3)


def test_better_bases_hold_irradiance_better():
    c = compare_bases(12, seed=3)
    s = {k: v["mean"] for k, v in c.summary().items()}
    # the same span over the hemisphere, so the same least-squares fit
    assert s["h 4"] == pytest.approx(s["sh 4"], rel=1e-9)
    assert s["modh 6"] == pytest.approx(s["h 6"], rel=1e-9)
    # more functions of a family never fit worse (nested spans)
    assert s["h 6"] < s["h 4"] and s["sh 9"] < s["sh 4"] and s["hsh 9"] < s["hsh 4"]
    # the H-basis's six hold irradiance better than any four, and nearly as well as SH's nine
    assert s["h 6"] < min(s[k] for k in s if k.endswith(" 4"))
    # a basis whose functions all vanish at the horizon (Makhotkin: sqrt(z)) is the worst of its count
    assert s["makhotkin 4"] == max(s[k] for k in s if k.endswith(" 4"))


def test_random_signals_are_deterministic_and_positive():
    a, b = random_signal(np.random.default_rng(5)), random_signal(np.random.default_rng(5))
    d, _ = hemisphere_quadrature(8, 16)
    np.testing.assert_array_equal(signal_irradiance(a, d), signal_irradiance(b, d))
    assert (signal_irradiance(a, d) >= 0).all()


def test_parse_basis_names_and_counts():
    assert [(b.name, c) for b, c in map(parse_basis, ["h6", "modh6", "sh9", "hl2", "zernike3", "hl23"])] == [
        ("h", 6), ("modh", 6), ("sh", 9), ("hl2", 3), ("zernike", 3), ("hl2", 3)]
    assert parse_entries(["sh-rh9", "h4"]) == [("sh-rh", 9), ("h", 4)]
    for bad in ("h7", "sh", "foo3", "hl24", "sh-rh5"):
        with pytest.raises(ArsimError):
            parse_entries([bad])


def test_bases_compare_end_to_end(tmp_path):
    result = arsim("bases", "compare", "-o", tmp_path, "--signals", "3", "--bases", "h6,modh6,hsh9,zernike6")
    assert result.returncode == 0, result.stderr
    for name in ("bases.md", "bases.json", "bases.png", "visual.png", "visual_errors.png"):
        assert (tmp_path / name).stat().st_size > 0
    data = json.loads((tmp_path / "bases.json").read_text())
    assert data["signals"] == 3 and set(data["errors"]) == {"h 6", "modh 6", "hsh 9", "zernike 6"}
    md = (tmp_path / "bases.md").read_text()
    assert "## 6 coefficients" in md and "## 9 coefficients" in md


@pytest.mark.parametrize("args, fragment", [
    (["--bases", "nosuch4"], "unknown basis 'nosuch'"),
    (["--bases", "h5"], "has 4 or 6 coefficients, not 5"),
    (["--signals", "0"], "--signals"),
    (["--sun-elevation", "120"], "--sun-elevation"),
])
def test_bases_compare_refuses_bad_input_in_one_line(tmp_path, args, fragment):
    assert_one_line_error(arsim("bases", "compare", "-o", tmp_path, *args), fragment)


def test_the_glsl_bases_equal_the_numpy_ones():
    """bases.glsl (what the renderer evaluates) against functions.py, float32 against float64."""
    from importlib import resources

    from arsim.core.gl import create_gl_context

    ctx = create_gl_context()
    source = resources.files("arsim.lighting").joinpath("shaders", "bases.glsl").read_text()
    d = np.random.default_rng(0).normal(size=(1024, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:4] = [[0, 0, 1], [1, 0, 0], [0, -1, 0], [0.6, 0, 0.8]]  # the pole and the horizon included
    directions = ctx.buffer(np.hstack([d, np.zeros((len(d), 1))]).astype("f4").tobytes())
    for name, basis in BASES.items():
        count = max(basis.counts)
        program = ctx.compute_shader(f"""#version 430
#define BASIS_{name.upper()}
#define BASIS_COUNT {count}
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer In {{ vec4 dirs[]; }};
layout(std430, binding = 1) writeonly buffer Out {{ float values[]; }};
{source}
void main() {{
    uint i = gl_GlobalInvocationID.x;
    float b[BASIS_COUNT];
    basis_values(dirs[i].xyz, b);
    for (int k = 0; k < BASIS_COUNT; k++) values[i * BASIS_COUNT + k] = b[k];
}}""")
        out = ctx.buffer(reserve=len(d) * count * 4)
        directions.bind_to_storage_buffer(0)
        out.bind_to_storage_buffer(1)
        program.run(len(d) // 64)
        values = np.frombuffer(out.read(), np.float32).reshape(len(d), count)
        np.testing.assert_allclose(values, basis.evaluate(d, count), atol=1e-5, err_msg=name)
        out.release()
        program.release()
