"""Direct alignment of two keyframes on a view features cannot pin (the interior's bare ceiling with one
lamp), with known orientations, distortion, fall-off and a different exposure in each."""

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.capture.direct import DirectImages, align_direct
from arsim.capture.refine import KeyframeFeatures
from arsim.core.assets import assets_dir
from arsim.core.conventions import CameraIntrinsics
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.sensors.camera import ResponseCurve, vignette
from arsim.sensors.views import environment_view_reference

CAMERA = CameraIntrinsics.from_fov(640, 480, 60.0, k1=-0.05, k2=0.01)


def _ceiling_views(exposures=(1.0, 1.6)):
    probe = to_layout(read_hdr(assets_dir() / "envmaps" / "interior.exr"), "anglemap", 256)
    curve = ResponseCurve()
    falloff = vignette(CAMERA.height, CAMERA.width, 0.3)[..., None]
    # looking up (camera +z towards world +y), the second view turned 4 degrees off and rolled 25 about its axis
    ra = Rotation.from_euler("X", -80, degrees=True)
    rb = ra * Rotation.from_euler("XYZ", [3.0, -2.5, 25.0], degrees=True)
    frames = []
    for r, gain in zip((ra, rb), exposures):
        radiance = environment_view_reference(probe, CAMERA, r)
        frames.append(curve.encode(np.clip(radiance * falloff * gain * 0.25 / float(np.median(radiance)), 0, 1)))
    linear = np.repeat(curve.decode(np.arange(256))[:, None], 3, axis=1)
    return frames, ra.inv() * rb, linear, falloff[..., 0]


def test_a_bare_ceiling_is_aligned_to_its_known_rotation():
    frames, truth, linear, falloff = _ceiling_views()
    features = KeyframeFeatures(CAMERA)
    images = DirectImages(features.camera, CAMERA, linear, falloff)
    a, b = (images(features.small(f)) for f in frames)
    for start in ([0.5, -0.4, 0.3], [-0.8, 0.2, -0.6]):  # the chain's error between keyframes, degrees
        match = align_direct(a, b, images, truth * Rotation.from_rotvec(np.radians(start)))
        assert match is not None and match.correlation > 0.99
        error = (match.rotation.inv() * truth).as_rotvec()
        assert np.degrees(np.linalg.norm(error)) < 0.02, np.degrees(error)
        # the covariance is of the right size: the error within 4 of its standard deviations on every axis
        assert error @ np.linalg.solve(match.covariance, error) < 16


def test_the_fall_off_left_in_would_pull_towards_no_rotation():
    """Without the fall-off divided out, the lens's vignette (fixed in the image) biases a bare view's
    alignment: what the images' linearisation is for."""
    frames, truth, linear, falloff = _ceiling_views(exposures=(1.0, 1.0))
    features = KeyframeFeatures(CAMERA)
    a_b = []
    for used in (falloff, np.ones_like(falloff)):
        images = DirectImages(features.camera, CAMERA, linear, used)
        a, b = (images(features.small(f)) for f in frames)
        match = align_direct(a, b, images, truth)
        a_b.append(np.degrees((match.rotation.inv() * truth).magnitude()) if match else np.inf)
    assert a_b[0] < 0.02 and a_b[1] > 2 * a_b[0], a_b


def test_views_that_do_not_overlap_are_not_aligned():
    frames, truth, linear, falloff = _ceiling_views()
    features = KeyframeFeatures(CAMERA)
    images = DirectImages(features.camera, CAMERA, linear, falloff)
    a, b = (images(features.small(f)) for f in frames)
    assert align_direct(a, b, images, truth * Rotation.from_euler("Y", 50, degrees=True)) is None


def test_shares_aligned_in_the_worker_process_give_the_same_matches_to_the_bit():
    """The refinement's shares of alignments (align_direct_all) computed in the worker process and by the caller's
    settle: each match the same as align_direct's here, rotation and covariance bit for bit."""
    from arsim.capture.direct import align_direct_all
    from arsim.core.worker import side_worker

    frames, truth, linear, falloff = _ceiling_views()
    features = KeyframeFeatures(CAMERA)
    images = DirectImages(features.camera, CAMERA, linear, falloff)
    a, b = (images(features.small(f)) for f in frames)
    starts = [truth * Rotation.from_rotvec(np.radians(s)) for s in ([0.5, -0.4, 0.3], [-0.8, 0.2, -0.6], [0.2, 0.9, 0.1])]
    jobs = [(a, b, start) for start in starts] + [(a, b, truth * Rotation.from_euler("Y", 50, degrees=True))]
    here = [align_direct(*job[:2], images, job[2]) for job in jobs]
    with side_worker() as side:
        futures = [side.call(align_direct_all, images, jobs[k:k + 1]) for k in range(len(jobs))]
        side.settle()
        there = [match for f in futures for match in f.result()]
    assert here[-1] is None and there[-1] is None
    for mine, theirs in zip(here[:-1], there[:-1]):
        assert np.array_equal(mine.rotation.as_quat(), theirs.rotation.as_quat())
        assert np.array_equal(mine.covariance, theirs.covariance)
