"""Light estimates in the platforms' shapes (arsim/estimate): the truth's SH against an independent
projection, the main light against the sun's centroid, the cubemap's mean against the environment's."""

import numpy as np
import pytest

from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.estimate.shapes import LUMA, cube_solid_angles, cubemap, estimate_light, main_light, sh_radiance
from arsim.lighting.bases.functions import sh9
from arsim.lighting.bases.irradiance import COSINE_KERNEL
from tests.conftest import ENVMAPS


def envmap(name, layout="anglemap", size=256):
    path = next(p for p in ENVMAPS if p.stem == name)
    return to_layout(read_hdr(path), layout, size)


def test_the_sh_of_the_radiance_equals_an_independent_projection():
    """The angle map's SH against the same texels projected on another basis: scipy's complex SH (with the
    Condon-Shortley phase) made real and orthonormal, in float64; within 1e-4 of the largest coefficient."""
    from scipy.special import sph_harm_y

    light = envmap("interior", "anglemap", 512)
    mine = sh_radiance(light)
    # the independent route: the same angle map's texels, but the basis from scipy (complex, with the
    # Condon-Shortley phase) in the pole-z frame, made real and orthonormal
    from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles

    inside = anglemap_disk_mask(512)
    d, omega = anglemap_directions(512)[inside], anglemap_solid_angles(512)[inside]
    theta, phi = np.arccos(np.clip(d[:, 2], -1, 1)), np.arctan2(d[:, 1], d[:, 0])
    basis = []
    for l in range(3):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi)
            basis.append(y.real if m == 0 else np.sqrt(2) * (-1) ** m * (y.real if m > 0 else y.imag))
    independent = np.stack(basis, axis=1).T @ (light[inside].astype(np.float64) * omega[:, None])
    assert np.abs(mine - independent).max() <= 1e-4 * np.abs(independent).max()


def test_the_main_light_of_the_sunrise_points_at_the_sun():
    """The sunrise's main light against the sun's centroid found on the equirect source at full resolution
    (the energy-weighted centroid of the texels within 5 degrees of its brightest): within 1 degree."""
    from arsim.core.conventions import equirect_directions, equirect_solid_angles

    path = next(p for p in ENVMAPS if p.stem == "sunrise")
    source = read_hdr(path)
    h = source.shape[0]
    d, omega = equirect_directions(h), equirect_solid_angles(h)
    luminance = source[..., :3] @ LUMA
    peak = d[np.unravel_index(np.argmax(luminance), luminance.shape)]
    near = (d @ peak) > np.cos(np.radians(5.0))
    w = (luminance * omega)[near]
    sun = (d[near] * w[:, None]).sum(axis=0)
    sun /= np.linalg.norm(sun)
    direction, intensity = main_light(to_layout(source, "anglemap", 512))
    assert np.degrees(np.arccos(np.clip(direction @ sun, -1, 1))) < 1.0
    assert (intensity > 0).all()


@pytest.mark.parametrize("name", ["interior", "sunrise", "city"])
def test_the_cubemap_keeps_the_spheres_mean(name):
    light = envmap(name, "anglemap", 512)
    estimate = estimate_light(light)
    faces = estimate.cubemap.astype(np.float64)
    mean_cube = (faces * cube_solid_angles(16)[None, :, :, None]).sum(axis=(0, 1, 2)) / (4 * np.pi)
    from arsim.core.conventions import anglemap_disk_mask, anglemap_solid_angles

    inside = anglemap_disk_mask(512)
    omega = anglemap_solid_angles(512)[inside]
    mean_env = (light[inside].astype(np.float64) * omega[:, None]).sum(axis=0) / omega.sum()
    assert (np.abs(mean_cube - mean_env) <= 0.01 * mean_env).all(), (mean_cube, mean_env)
    assert np.isclose(cube_solid_angles(16).sum() * 6, 4 * np.pi)
    assert cubemap(light).shape == (6, 16, 16, 3)


def test_cube_texels_and_directions_agree_and_the_faces_are_where_opengl_puts_them():
    from arsim.estimate.shapes import cube_directions, cube_texels

    d = cube_directions(16)
    face, row, col = cube_texels(d.reshape(-1, 3), 16)
    f, r, c = np.meshgrid(np.arange(6), np.arange(16), np.arange(16), indexing="ij")
    assert (face == f.ravel()).all() and (row == r.ravel()).all() and (col == c.ravel()).all()
    # GL's table: +X face, s along -z, t along -y; +Y face, s along +x, t along +z
    assert np.allclose(d[0, 0, 0], np.array([1, 1, 1]) / np.sqrt(3), atol=0.1)  # (s, t) = (-1, -1): -(-z), -(-y)
    assert d[2, 8, 15, 0] > 0.6 and d[2, 15, 8, 2] > 0.6 and (d[2, ..., 1] > 0).all()
    # a light bright above only: the +Y face bright, the -Y face dark
    from arsim.core.conventions import anglemap_directions

    above = np.repeat((anglemap_directions(256)[..., 1] > 0.5)[..., None], 3, axis=-1).astype(np.float32)
    faces = cubemap(above)
    assert faces[2].mean() > 0.5 and faces[3].max() == 0.0


def test_the_metrics_behave_as_defined_on_known_cases():
    """Identical renders give 0 everywhere; a uniform scale of the light gives si-RMSE 0 and angular error
    0 but an RMSE above 0; the environment turned by 90 degrees about the vertical turns the main light by
    the angle that turn makes with its direction (90 degrees for a light on the horizon)."""
    from scipy.spatial.transform import Rotation

    from arsim.core.conventions import anglemap_directions
    from arsim.core.resample import sample_anglemap
    from arsim.evaluate import light_metrics as m

    rng = np.random.default_rng(3)
    render = rng.uniform(0.1, 2.0, (32, 32, 3))
    mask = rng.random((32, 32)) > 0.3
    for f in (m.rmse, m.si_rmse, m.angular_error_deg):
        assert f(render, render, mask) < 1e-9
    assert m.sh_relative_error(render[:9, 0], render[:9, 0]) == 0.0
    assert m.si_rmse(2.5 * render, render, mask) < 1e-9 and m.angular_error_deg(2.5 * render, render, mask) < 1e-6
    assert m.rmse(2.5 * render, render, mask) > 1.0
    light = envmap("sunrise", "anglemap", 512)
    turn = Rotation.from_rotvec([0.0, np.pi / 2, 0.0]).as_matrix()
    turned = sample_anglemap(light, anglemap_directions(512) @ turn).astype(np.float32)  # L'(d) = L(R^T d)
    d0, _ = main_light(light)
    d1, _ = main_light(turned)
    expected = np.degrees(np.arccos(np.clip(d0 @ (turn @ d0), -1, 1)))
    assert 85.0 < expected <= 90.0  # (the sun of the sunrise is near the horizon)
    assert abs(m.direction_error_deg(d1, d0) - expected) < 1.0
    assert m.direction_error_deg(d1, turn @ d0) < 1.0


GOOD = {"sh_radiance": [0.1] * 27, "main_light": {"direction_world": [0.0, 1.0, 0.0], "intensity_rgb": [1.0, 1.0, 1.0]},
        "ambient_intensity": 0.5, "color_correction": [1.0, 1.0, 1.0, 0.5]}


def write_lines(path, lines):
    import json

    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return path


@pytest.mark.parametrize("change, fragment", [
    (lambda ls: ls[1].pop("main_light"), 'line 2: no "main_light"'),
    (lambda ls: ls[2].update(sh_radiance=[0.1] * 26), "line 3: sh_radiance needs 27 finite numbers (got 26"),
    (lambda ls: ls[0].update(ambient_intensity=float("nan")), "line 1: ambient_intensity needs a finite number"),
    (lambda ls: ls[2].update(frame=1), "line 3: frame 1 comes after frame 1"),
    (lambda ls: ls[1]["main_light"].update(direction_world=[0.0, 0.0]), "line 2: main_light needs direction_world"),
])
def test_a_bad_estimates_file_is_refused_naming_the_line(tmp_path, change, fragment):
    import copy

    from arsim.core.errors import ArsimError
    from arsim.estimate.series import read_estimates

    lines = [dict(copy.deepcopy(GOOD), frame=k) for k in range(3)]
    assert len(read_estimates(write_lines(tmp_path / "ok.jsonl", lines), 10)) == 3
    change(lines)
    with pytest.raises(ArsimError, match=fragment.replace("(", r"\(").replace('"', '"')):
        read_estimates(write_lines(tmp_path / "bad.jsonl", lines), 10)


def test_arsim_estimate_scores_the_capture_and_a_file_and_refuses_a_bad_file(tmp_path):
    """A 2 s sweep: estimates.jsonl (a line a frame, the truth's in each, the capture's once it has a
    snapshot, the file's where given), scores.json with the capture's and the file's scores; the file's
    estimate is the truth's SH scaled by 2 (SH error 100 %); a file with a line of 26 SH floats: one line,
    exit status 2, nothing written."""
    import json

    from tests.test_cli import arsim, assert_one_line_error

    (tmp_path / "s.toml").write_text('[run]\nseed = 3\n[environment]\nmap = "envmaps/courtyard.exr"\nprobe_size = 128\n'
                                     '[capture]\nduration_s = 2.0\ncapture_size = 64\n[device.camera]\nwidth = 96\n'
                                     'height = 72\n[ar]\nenabled = false\n')
    r = arsim("record", tmp_path / "s.toml", "-o", tmp_path / "rec")
    assert r.returncode == 0, r.stderr
    bad = write_lines(tmp_path / "bad.jsonl", [dict(GOOD, frame=0), dict(GOOD, frame=1, sh_radiance=[0.0] * 26)])
    assert_one_line_error(arsim("estimate", tmp_path / "rec", "-o", tmp_path / "bad", "--file", bad),
                          "bad.jsonl, line 2: sh_radiance needs 27")
    assert not (tmp_path / "bad").exists()
    # the truth's SH, doubled, as a user's estimate for every frame
    r = arsim("estimate", tmp_path / "rec", "-o", tmp_path / "est")
    assert r.returncode == 0, r.stderr
    lines = [json.loads(x) for x in (tmp_path / "est" / "estimates.jsonl").read_text().splitlines()]
    mine = [dict(GOOD, frame=line["frame"], sh_radiance=[2 * v for v in line["truth"]["sh_radiance"]],
                 main_light=line["truth"]["main_light"]) for line in lines]
    r = arsim("estimate", tmp_path / "rec", "-o", tmp_path / "est2", "--file", write_lines(tmp_path / "mine.jsonl", mine))
    assert r.returncode == 0, r.stderr
    scores = json.loads((tmp_path / "est2" / "scores.json").read_text())
    assert abs(scores["file"]["final"]["sh_error"] - 1.0) < 1e-9 and scores["file"]["final"]["main_light_error_deg"] < 1e-6
    assert scores["capture"]["frames"] >= 1 and "capture" in lines[-1] and len(lines) == scores["file"]["frames"]
    assert set(scores["capture"]["spheres"]) == {"diffuse", "silver", "mirror"} and set(scores["file"]["spheres"]) == {"diffuse"}
    # the truth's own estimate is scored by its spheres (what the shapes allow): closer than one frame's view
    assert set(scores["truth"]) == {"spheres"}
    assert scores["truth"]["spheres"]["diffuse"]["rmse"] < scores["single"]["spheres"]["diffuse"]["rmse"]
    assert (tmp_path / "est2" / "spheres.png").stat().st_size > 1000
    # the main light in the camera's frame: the world direction turned by the phone's camera orientation
    from arsim.capture.pipeline import fused_camera_orientations
    from arsim.sensors.recording import load_recording

    views = fused_camera_orientations(load_recording(tmp_path / "rec")).as_matrix()
    light = lines[-1]["truth"]["main_light"]
    np.testing.assert_allclose(views[-1] @ np.array(light["direction_camera"]), light["direction_world"], atol=1e-9)
    arcore = json.loads((tmp_path / "est2" / "platforms" / "capture_arcore.json").read_text())
    assert len(arcore["ambientSphericalHarmonics"]) == 27 and len(arcore["cubemap"]) == 6
    assert {"truth_arkit.json", "single_webxr.json"} <= {p.name for p in (tmp_path / "est2" / "platforms").iterdir()}


def test_the_truths_own_estimate_lights_the_spheres_as_the_truth_does():
    """The three spheres lit by the truth's own estimate against the same lit by the truth: the diffuse
    sphere within what its SH ambient and main light hold (a few percent), the silver and mirror within what a
    16 x 16 cubemap holds; a light scaled by 2 gives si-RMSE 0 (to rounding) and RMSE 1 on every sphere."""
    from arsim.estimate.shapes import estimate_light
    from arsim.evaluate.spheres import estimate_spheres, sphere_scores, truth_spheres

    light = envmap("interior", "anglemap", 256)
    truth = truth_spheres(light)
    e = estimate_light(light)
    mine = estimate_spheres(e.sh_radiance, e.main_light_direction, e.main_light_intensity, e.cubemap)
    scores = sphere_scores(mine, truth)
    assert scores["diffuse"]["rmse"] < 0.03 and scores["diffuse"]["angular_deg"] < 2.0, scores
    # The main light as a directional light beside the SH ambient (estimate.lit) holds the sun the SH's
    # nine coefficients smear: on the sunrise, less than half the error of the SH alone (0.017 against 0.044).
    sun = envmap("sunrise", "anglemap", 256)
    s = estimate_light(sun)
    split, sh_alone = (sphere_scores(estimate_spheres(s.sh_radiance, s.main_light_direction, k * s.main_light_intensity, None),
                                     truth_spheres(sun))["diffuse"]["rmse"] for k in (1.0, 0.0))
    assert split < 0.5 * sh_alone, (split, sh_alone)
    assert scores["silver"]["rmse"] < 0.25 and scores["mirror"]["hdr_flip"] > 0.0, scores
    doubled = sphere_scores(2 * truth, truth)
    for name in ("diffuse", "silver", "mirror"):
        assert doubled[name]["si_rmse"] < 1e-9 and abs(doubled[name]["rmse"] - 1.0) < 1e-9
    assert sphere_scores(truth, truth)["mirror"]["hdr_flip"] == 0.0


def test_the_single_frame_estimator_sees_a_uniform_light_and_points_at_a_bright_patch():
    """A frame of one code everywhere (a uniform light, linear codes): its SH is the uniform light's (every
    direction within 1 %), its colour correction neutral; a brighter patch right of the image's centre,
    seen by a camera turned a quarter turn: the main light points at the patch's world direction within 2°."""
    from scipy.spatial.transform import Rotation

    from arsim.core.conventions import CameraIntrinsics
    from arsim.estimate.single_frame import SingleFrameEstimator
    from arsim.lighting.bases.functions import sh9

    camera = CameraIntrinsics.from_fov(320, 240, 60.0)
    estimator = SingleFrameEstimator(camera)
    linear = np.repeat(np.linspace(0.0, 1.0, 256)[:, None], 3, axis=1)
    codes = np.full((240, 320, 3), 128, np.uint8)
    e = estimator.estimate(codes, linear, np.eye(3))
    d = np.random.default_rng(0).normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(sh9(d) @ e.sh_radiance, linear[128][None].repeat(500, axis=0), rtol=0.01)
    np.testing.assert_allclose(e.color_correction[:3], 1.0, atol=1e-9)
    codes[:] = 40  # a dim room ...
    codes[100:140, 240:280] = 249  # ... and a lamp (under the clipped codes)
    turn = Rotation.from_rotvec([0.0, np.pi / 2, 0.0]).as_matrix()
    e = estimator.estimate(codes, linear, turn)
    patch = turn @ camera.unproject(np.array([259.5, 119.5]))
    assert np.degrees(np.arccos(np.clip(e.main_light_direction @ patch, -1, 1))) < 2.0


def test_the_platforms_structures_give_back_the_irradiance_and_the_neutral_colour():
    """ARCore's coefficients with the factors its samples premultiply them by (Y_lm's constant, the cosine's
    convolution over pi, and its basis's signs: 0.282095, -0.325735, 0.325735, -0.325735, 0.273137,
    -0.273137, 0.078848, -0.273137, 0.136569) and its shader's polynomials give arsim's E(n) / pi; ARKit's
    three planes are the same numbers; a grey light is 6500 K (+-100: sRGB's white is D65)."""
    from arsim.estimate.platforms import PLATFORMS, color_temperature_k
    from arsim.estimate.shapes import estimate_light
    from arsim.lighting.bases.functions import sh9
    from arsim.lighting.bases.irradiance import COSINE_KERNEL

    light = envmap("city", "anglemap", 128)
    e = estimate_light(light)
    n = np.random.default_rng(2).normal(size=(100, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ours = sh9(n) @ (e.sh_radiance * COSINE_KERNEL[:, None]) / np.pi
    factors = np.array([0.282095, -0.325735, 0.325735, -0.325735, 0.273137, -0.273137, 0.078848, -0.273137, 0.136569])
    x, y, z = n.T
    poly = np.stack([np.ones_like(x), y, z, x, y * x, y * z, 3 * z * z - 1, z * x, x * x - y * y], axis=1)
    coefficients = np.array(PLATFORMS["arcore"](e)["ambientSphericalHarmonics"]).reshape(9, 3)
    theirs = poly @ (coefficients * factors[:, None])
    np.testing.assert_allclose(theirs, ours, rtol=1e-5, atol=1e-6 * np.abs(ours).max())
    planes = np.array(PLATFORMS["arkit"](e)["sphericalHarmonicsCoefficients"]).reshape(3, 9)
    np.testing.assert_allclose(planes.T, e.sh_radiance, rtol=1e-12)
    assert len(PLATFORMS["webxr"](e)["sphericalHarmonicsCoefficients"]) == 27
    assert abs(color_temperature_k(np.ones(3)) - 6500) < 100
    assert color_temperature_k(np.array([1.0, 0.6, 0.3])) < 4000 < 9000 < color_temperature_k(np.array([0.6, 0.8, 1.2]))


def test_an_estimate_lights_as_maps_a_uniform_light_gives_its_radiance_and_a_sun_its_cosine():
    """estimate.lit: the maps of a uniform light's estimate are that radiance (irradiance over pi, and every
    lobe average), its environment too; a sun of known irradiance beside a dim sky gives the irradiance map
    the sun's clamped cosine within 1 % of the sun's part, where the SH alone rings."""
    from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
    from arsim.estimate.lit import environment, estimate_maps
    from arsim.estimate.shapes import estimate_light

    size = 64
    uniform = np.zeros((size, size, 3), np.float32)
    uniform[anglemap_disk_mask(size)] = (0.5, 1.0, 2.0)
    e = estimate_light(uniform)
    maps = estimate_maps(e, {"fast": [1.0, 20.0, 500.0], "mipmap": [20.0]}, 32, "uniform")
    inside = anglemap_disk_mask(32)
    for name, exponents in (("fast", (1.0, 20.0, 500.0)), ("mipmap", (1.0, 20.0))):
        assert maps[name].exponents == exponents and maps[name].source == "uniform"
        # (the reflection maps within the cubemap's own texels' binning of the light, 1 %)
        for s in exponents:
            assert np.allclose(maps[name][s][inside], (0.5, 1.0, 2.0), rtol=1e-3 if s == 1.0 else 1e-2), (name, s)
    assert np.allclose(environment(e, 32)[inside], (0.5, 1.0, 2.0), rtol=1e-5)

    side = 512
    light = np.zeros((side, side, 3), np.float32)
    disk = anglemap_disk_mask(side)
    light[disk] = 0.05
    d = anglemap_directions(side)
    sun_dir = np.array([0.3, 0.8, 0.52]) / np.linalg.norm([0.3, 0.8, 0.52])
    sun = disk & (d @ sun_dir > np.cos(np.radians(1.5)))
    light[sun] = 2000.0
    e = estimate_light(light)
    normals = anglemap_directions(32)[inside]
    irradiance_map = estimate_maps(e, {"fast": [1.0]}, 32, "sun")["fast"][1.0][inside][:, 1]
    from arsim.core.conventions import anglemap_solid_angles

    sun_e = 2000.0 * anglemap_solid_angles(side)[sun].sum()
    exact = (0.05 * np.pi + sun_e * np.maximum(normals @ sun_dir, 0.0)) / np.pi
    assert np.abs(irradiance_map - exact).max() < 0.01 * sun_e / np.pi
    sh_alone = np.maximum(sh9(normals) @ (e.sh_radiance[:, 1] * COSINE_KERNEL), 0.0) / np.pi
    assert np.abs(sh_alone - exact).max() > 0.05 * sun_e / np.pi


def test_compiled_lobe_averages_equal_the_numpy_reference():
    """estimate.lit.lobe_averages_of (every exponent from one pass, negligible terms skipped) equals
    lobe_average_of exponent by exponent, wide and narrow lobes, on a light with a bright spot."""
    from arsim.estimate.lit import lobe_average_of, lobe_averages_of
    from arsim.estimate.shapes import cube_directions, cube_solid_angles

    rng = np.random.default_rng(4)
    side = 16
    samples = cube_directions(side).reshape(-1, 3)
    weights = np.tile(cube_solid_angles(side).reshape(-1), 6)
    radiance = rng.random((len(samples), 3)) * 0.2
    radiance[100] = (500.0, 400.0, 300.0)
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    exponents = [2.0, 10.0, 80.0, 1280.0, 100000.0]
    compiled = lobe_averages_of(samples, radiance, weights, d, exponents)
    for k, s in enumerate(exponents):
        np.testing.assert_allclose(compiled[k], lobe_average_of(samples, radiance, weights, d, s), rtol=1e-10, atol=1e-14)
