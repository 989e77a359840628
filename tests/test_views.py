"""Camera views of the environment: the GL renderer agrees with the NumPy reference, and looks where
the conventions say."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics, anglemap_st_to_pixel, direction_to_anglemap_st
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.sensors.trajectory import CAMERA_TO_DEVICE, CaptureSweep
from arsim.sensors.views import EnvironmentRenderer, environment_view_reference
from tests.conftest import ENVMAPS

CAMERA = CameraIntrinsics.from_fov(160, 120, 60.0)


@pytest.fixture(scope="module")
def renderer_and_probe():
    probe = to_layout(read_hdr(ENVMAPS[1]), "anglemap", 256)
    return EnvironmentRenderer(probe, CAMERA), probe


@pytest.mark.parametrize("t", [0.0, 17.0, 30.0, 44.0, 60.0])
def test_gl_view_matches_the_numpy_reference(renderer_and_probe, t):
    # Stated tolerance: llvmpipe and GPUs interpolate bilinearly with 8-bit weights, float32 maths.
    renderer, probe = renderer_and_probe
    rotation = CaptureSweep().camera_orientation([t])[0]
    gl = renderer.render(rotation)
    ref = environment_view_reference(probe, CAMERA, rotation)
    rel = np.abs(gl - ref) / (ref + 1e-3 * ref.mean())
    assert rel.max() < 1e-2 and rel.mean() < 1e-3


def test_a_bright_direction_appears_at_its_projected_pixel():
    n = 128
    probe = np.full((n, n, 3), 0.1, dtype=np.float32)
    target = np.array([0.3, 0.2, -1.0])
    target /= np.linalg.norm(target)
    row, col = (int(round(float(v))) for v in anglemap_st_to_pixel(direction_to_anglemap_st(target), n))
    probe[row, col] = 1000.0
    upright = Rotation.from_matrix(CAMERA_TO_DEVICE)  # device upright, camera looking along world -z
    image = EnvironmentRenderer(probe, CAMERA).render(upright)
    peak = np.unravel_index(np.argmax(image[..., 0]), image.shape[:2])
    expected = CAMERA.project(upright.inv().apply(target)[None])[0]  # (u, v)
    assert abs(peak[1] - expected[0]) <= 2 and abs(peak[0] - expected[1]) <= 2
    assert expected[0] > CAMERA.cx and expected[1] < CAMERA.cy  # +x is right and +y is up in the picture


def test_gl_view_with_lens_distortion_matches_the_reference(renderer_and_probe):
    _, probe = renderer_and_probe
    camera = CameraIntrinsics.from_fov(160, 120, 70.0, k1=-0.15, k2=0.02)
    rotation = CaptureSweep().camera_orientation([25.0])[0]
    gl = EnvironmentRenderer(probe, camera).render(rotation)
    ref = environment_view_reference(probe, camera, rotation)
    rel = np.abs(gl - ref) / (ref + 1e-3 * ref.mean())
    assert rel.max() < 1e-2 and rel.mean() < 1e-3


@pytest.mark.parametrize("response, gamma", [("srgb", 2.2), ("gamma", 2.2), ("s-curve", 2.2), ("gamma", 10.0),
                                             ("gamma", 0.1)])
def test_gl_camera_frames_equal_the_numpy_sensor_model(renderer_and_probe, response, gamma):
    """The GL camera (one pass: view, noise, gain, response, 8 bits) against camera.expose applied to
    the GL radiance with the same hashed noise. Stated tolerance: identical codes on llvmpipe; a GPU
    that fuses multiply-adds may move a sample across a code threshold, so up to 1e-4 of the samples
    may differ by one code."""
    from arsim.sensors.camera import ResponseCurve, SensorSettings, expose, noise_key, pixel_normals, vignette
    from arsim.sensors.views import CameraRenderer

    _, probe = renderer_and_probe
    sensor, curve = SensorSettings(), ResponseCurve(response, gamma=gamma)  # steep gammas: guesses many codes off
    camera = CameraRenderer(probe, CAMERA, sensor, curve)
    rotation = CaptureSweep().camera_orientation([17.0])[0]
    radiance = camera.render(rotation)
    lit = []
    for k, (exposure, iso) in enumerate([(1 / 30, 100.0), (1 / 500, 800.0), (1 / 8000, 50.0), (1 / 2, 400.0)]):
        key = noise_key(4, "capture", k)
        gl = camera.capture(rotation, exposure, iso, key)
        ref = expose(radiance, exposure, iso, sensor, curve, pixel_normals(key, CAMERA.height, CAMERA.width),
                     vignette(CAMERA.height, CAMERA.width, sensor.vignetting))
        diff = np.abs(gl.astype(int) - ref)
        assert diff.max() <= 1 and np.mean(diff > 0) <= 1e-4
        assert 5 < ref.mean() < 250 or k >= 2 or gamma != 2.2  # the settings span dark to bright frames
        lit.append(np.mean((ref > 0) & (ref < 255)))
    assert max(lit) > 0.05  # a frame of the steep curves too has many codes off the ends
    camera.release()


def test_gl_view_of_the_table_and_tag_matches_the_reference(renderer_and_probe):
    """Along the AR path the table and the printed tag appear where the NumPy ray cast puts them.
    Stated tolerance: mean relative difference below 1 %; at most 2 % of the pixels (the table's and
    the sheet's edges, where GL filters the tag's mip chain and the reference does not) differ by more
    than 1 %."""
    from arsim.sensors.table import Table
    from arsim.sensors.trajectory import ARPath, camera_mount

    _, probe = renderer_and_probe
    table = Table(tag_id=3)
    camera = CameraIntrinsics.from_fov(640, 480, 60.0)  # fine enough that the tag's texels are magnified
    renderer = EnvironmentRenderer(probe, camera, table=table)
    path, mount = ARPath(duration=20.0, laps=0.5, look_away=((8.0, 11.0),)), camera_mount((0.0, 0.0, 0.0))
    for t in (0.0, 4.0, 16.0):
        rotation, position = path.camera_orientation([t], mount)[0], path.position([t])[0]
        gl = renderer.render(rotation, position)
        ref = environment_view_reference(probe, camera, rotation, position, table)
        rel = np.abs(gl - ref) / (ref + 1e-3 * ref.mean())
        assert rel.mean() < 1e-2 and np.mean(rel > 1e-2) < 0.02
        sheet = np.isclose(ref[..., 0] / renderer.table_light[0], 0.8, atol=1e-6)  # white paper pixels
        assert sheet.sum() > 20  # the tag is in view at these times
    renderer.release()
