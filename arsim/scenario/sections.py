"""The sections of a scenario file. Adding a section: write its dataclass here, add it to Scenario."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from arsim.core.conventions import map_size_problem
from arsim.core.tags import DEFAULT_DETECTOR, DETECTORS, TAG_FAMILIES, detector_problem
from arsim.lighting.methods import LOOP_METHODS, METHODS
from arsim.scenario.schema import setting, subsection


@dataclass(frozen=True)
class RunSection:
    """[run]: what the run is called and the seed every random stream derives from."""

    name: str = setting("default", help="name of the run, used in reports and file names")
    seed: int = setting(0, min=0, max=2**32 - 1, help="seed of every random stream of the run")


@dataclass(frozen=True)
class EnvironmentSection:
    """[environment]: the true HDR environment around the scene (the ground truth of the light)."""

    map: Path = setting(
        Path("envmaps/interior.exr"),
        must_exist=True,
        help="HDR environment (.exr or .hdr, equirect 2:1 or angle map 1:1); relative to the scenario, then to assets/",
    )
    probe_size: int = setting(512, min=16, max=4096, unit="texels", help="N of the N x N angle map the environment is held in")
    intensity: float = setting(1.0, min=0.0, max=1e6, help="factor applied to the environment's radiance")
    yaw_deg: float = setting(0.0, min=-360.0, max=360.0, unit="degrees", help="rotation of the environment about world +y")


# ---------------------------------------------------------------------------------------------------
# [device]: the phone's IMU and camera. IMU units are SI as Android reports them (rad/s, m/s², µT).
# Datasheets print noise densities otherwise: 2.8 mdps/sqrt(Hz) = 4.887e-5 rad/s/sqrt(Hz) and
# 70 µg/sqrt(Hz) = 6.865e-4 m/s²/sqrt(Hz). Defaults: TDK ICM-42688-P (noise, ranges, 19/18-bit FIFO data)
# and AKM AK09918 (range, resolution); biases, scale factors and misalignments are typical residuals
# after a phone's own calibration (no datasheet gives them).

_DEG = 0.017453292519943295
_G = 9.80665


@dataclass(frozen=True)
class ImuSensorSection:
    """[device.gyroscope], [device.accelerometer], [device.magnetometer]: one three-axis sensor, in its
    Android unit U (rad/s, m/s², µT); each table has its own defaults (GYROSCOPE, ... below)."""

    rate_hz: float = setting(200.0, min=0.1, max=10000.0, unit="Hz", help="output data rate")
    noise_density: float = setting(0.0, min=0.0, max=100.0, help="white noise, U/sqrt(Hz)")
    bias_random_walk: float = setting(0.0, min=0.0, max=100.0, help="bias random walk, U/sqrt(s)")
    bias_instability: float = setting(0.0, min=0.0, max=100.0, help="Gauss-Markov bias, U")
    bias_correlation_s: float = setting(100.0, min=0.01, max=1e6, unit="s", help="its correlation time")
    turn_on_bias: float = setting(0.0, min=0.0, max=1000.0, help="per-axis turn-on bias (or residual hard iron), U")
    scale_factor: float = setting(0.0, min=0.0, max=0.5, help="per-axis scale-factor error (fraction; soft iron)")
    misalignment_rad: float = setting(0.0, min=0.0, max=0.5, unit="rad", help="cross-axis terms")
    full_scale: float = setting(1e5, min=0.01, max=1e5, help="saturation, U")
    resolution: float = setting(0.0, min=0.0, max=100.0, help="LSB, U (0: none)")
    jitter_s: float = setting(0.0, min=0.0, max=0.1, unit="s", help="timestamp jitter")


GYROSCOPE = ImuSensorSection(
    rate_hz=200.0, noise_density=2.8e-3 * _DEG, bias_random_walk=2e-5, bias_instability=5e-5,
    bias_correlation_s=100.0, turn_on_bias=0.05 * _DEG, scale_factor=0.005, misalignment_rad=0.005,
    full_scale=2000 * _DEG, resolution=4000 * _DEG / 2**19, jitter_s=2e-5)
ACCELEROMETER = ImuSensorSection(
    rate_hz=200.0, noise_density=70e-6 * _G, bias_random_walk=1e-4, bias_instability=2e-3,
    bias_correlation_s=200.0, turn_on_bias=0.02 * _G, scale_factor=0.005, misalignment_rad=0.01,
    full_scale=16 * _G, resolution=32 * _G / 2**18, jitter_s=2e-5)
MAGNETOMETER = ImuSensorSection(
    rate_hz=50.0, noise_density=0.1, bias_random_walk=0.0, bias_instability=0.0, bias_correlation_s=100.0,
    turn_on_bias=0.5, scale_factor=0.01, misalignment_rad=0.01, full_scale=4900.0, resolution=0.15, jitter_s=1e-4)


@dataclass(frozen=True)
class CameraSection:
    """[device.camera]: the back camera, its sensor and its auto-exposure."""

    width: int = setting(640, min=16, max=8192, unit="pixels", help="image width")
    height: int = setting(480, min=16, max=8192, unit="pixels", help="image height")
    hfov_deg: float = setting(60.0, min=1.0, max=179.0, unit="degrees", help="horizontal field of view (under 180)")
    fps: float = setting(30.0, min=0.1, max=1000.0, unit="Hz", help="frame rate")
    k1: float = setting(0.0, min=-1.0, max=1.0, help="radial distortion k1 (OpenCV model)")
    k2: float = setting(0.0, min=-1.0, max=1.0, help="radial distortion k2 (OpenCV model)")
    response: str = setting("s-curve", choices=("srgb", "gamma", "s-curve"), help="response curve")
    gamma: float = setting(2.2, min=0.1, max=10.0, help="exponent of the gamma response")
    contrast: float = setting(2.0, min=0.01, max=10.0, help="strength of the S-curve")
    sensitivity: float = setting(4.0, min=1e-6, max=1e6, help="1/(radiance x s) that saturates a pixel at base ISO")
    full_well_e: float = setting(6000.0, min=1.0, max=1e7, unit="electrons", help="electrons at saturation")
    read_noise_e: float = setting(3.0, min=0.0, max=1e4, unit="electrons", help="read noise")
    base_iso: float = setting(100.0, min=1.0, max=1e5, help="ISO of unit gain")
    iso_min: float = setting(100.0, min=1.0, max=1e6, help="lowest ISO")
    iso_max: float = setting(3200.0, min=1.0, max=1e6, help="highest ISO")
    exposure_min_s: float = setting(1e-5, min=1e-9, max=10.0, unit="s", help="shortest exposure")
    exposure_max_s: float = setting(1 / 30, min=1e-9, max=10.0, unit="s", help="longest exposure")
    vignetting: float = setting(0.3, min=0.0, max=1.0, help="fall-off at the corners")
    target_grey: float = setting(0.18, min=0.001, max=1.0, help="metered level the auto-exposure aims for")
    convergence: float = setting(0.6, min=0.01, max=1.0, help="fraction of the log error corrected per frame")
    latency_frames: int = setting(3, min=0, max=30, unit="frames", help="delay before new settings apply")
    settle_frames: int = setting(16, min=1, max=1000, unit="frames", help="frames the auto-exposure takes to settle")

    def rules(self) -> str | None:
        if self.iso_min > self.iso_max:
            return f"iso_min = {self.iso_min:g} is above iso_max = {self.iso_max:g}: give iso_min <= iso_max"
        if self.exposure_min_s > self.exposure_max_s:
            return (f"exposure_min_s = {self.exposure_min_s:g} is above exposure_max_s = {self.exposure_max_s:g}: "
                    "give exposure_min_s <= exposure_max_s")
        return None


@dataclass(frozen=True)
class DeviceSection:
    """[device]: the phone."""

    gyroscope: ImuSensorSection = subsection(ImuSensorSection, help="gyroscope (rad/s)", default=GYROSCOPE)
    accelerometer: ImuSensorSection = subsection(ImuSensorSection, help="accelerometer (m/s²)", default=ACCELEROMETER)
    magnetometer: ImuSensorSection = subsection(ImuSensorSection, help="magnetometer (µT)", default=MAGNETOMETER)
    camera: CameraSection = subsection(CameraSection, help="back camera")
    camera_misalignment_deg: tuple[float, float, float] = setting(
        (0.0, 0.0, 0.0), min=-10.0, max=10.0, unit="degrees",
        help="x, y, z rotation of the camera against the IMU (device) axes beyond the nominal back-camera mount")


@dataclass(frozen=True)
class CaptureSection:
    """[capture]: the sweep that captures the light probe."""

    duration_s: float = setting(60.0, min=1.0, max=3600.0, unit="s", help="length of the sweep")
    turns: float = setting(5.0, min=0.5, max=50.0, help="full turns about the vertical")
    pitch_from_deg: float = setting(-75.0, min=-90.0, max=90.0, unit="degrees", help="pitch at the start (down)")
    pitch_to_deg: float = setting(75.0, min=-90.0, max=90.0, unit="degrees", help="pitch at the end (up)")
    roll_wobble_deg: float = setting(3.0, min=0.0, max=45.0, unit="degrees", help="hand roll wobble")
    sway_m: float = setting(0.03, min=0.0, max=1.0, unit="m", help="hand sway")
    fusion: str = setting("game-rotation-vector", choices=("game-rotation-vector", "rotation-vector"),
                          help="orientation the app reads")
    burst_frames: int = setting(13, min=0, max=64, unit="frames",
                                help="bracketed burst at the start pose for response calibration (0: none)")
    burst_step: float = setting(1.41421356, min=1.01, max=16.0,
                                help="exposure ratio between burst frames (half stops: Robertson sees every code from several exposures)")
    bracket_ev: tuple[float, ...] = setting((0.0, -7.0, -14.0), min=-30.0, max=30.0, unit="EV",
                                            help="exposure offsets the sweep's frames cycle through, the first 0 "
                                                 "(metered; the others capture highlights)")
    align_every: int = setting(1, min=0, max=1000, unit="frames",
                               help="capture: align every K-th metered frame against the probe (0: never)")
    refine: bool = setting(True, help="capture: refine every keyframe's orientation at once after the online pass "
                                      "(loop closures and gyroscope priors) and accumulate the probe again with them")
    capture_size: int = setting(512, min=16, max=4096, unit="texels", help="capture: N of the captured N x N angle map")


@dataclass(frozen=True)
class LookAwaySection:
    """[[ar.look_away]]: a time window in which the phone looks away from the tag (it is lost)."""

    start_s: float = setting(8.0, min=0.0, max=3600.0, unit="s", help="when the view starts to swing away")
    end_s: float = setting(11.0, min=0.0, max=3600.0, unit="s", help="when it is back on the tag")

    def rules(self) -> str | None:
        """The cross-field rule (parse_section applies each section's rules once it is built)."""
        return None if self.start_s < self.end_s else f"start_s = {self.start_s} is not before end_s = {self.end_s}"


@dataclass(frozen=True)
class ArSection:
    """[ar]: the AR session's walk around the table, the printed AprilTag on it and the table itself.
    World: the table top is y = 0, the tag lies centred at the origin, its x axis along world +x."""

    enabled: bool = setting(True, help="record the AR path (into ar/ of the recording) after the sweep")
    duration_s: float = setting(20.0, min=1.0, max=3600.0, unit="s", help="length of the AR path")
    laps: float = setting(0.5, min=0.0, max=20.0, help="times around the tag")
    near_m: float = setting(0.3, min=0.05, max=10.0, unit="m", help="closest distance to the tag")
    far_m: float = setting(1.5, min=0.05, max=10.0, unit="m", help="farthest distance to the tag")
    shake_deg: float = setting(0.5, min=0.0, max=10.0, unit="degrees", help="hand shake")
    look_away: tuple[LookAwaySection, ...] = subsection(LookAwaySection, array=True, default=(LookAwaySection(),),
                                                      help="windows in which the tag leaves the view")
    tag_family: str = setting("tag36h11", choices=tuple(TAG_FAMILIES),
                              help="the printed tag's family: AprilTag's tag36h11, tag25h9, tag16h5, or ArUco's aruco4x4_50")
    tag_id: int = setting(0, min=0, max=586, help="id of the printed tag (tag36h11 has 587, tag25h9 35, tag16h5 30, "
                                                  "aruco4x4_50 50)")
    fusion: bool = setting(True, help="fuse the tag's poses with the IMU (an error-state Kalman filter): smoother poses, "
                                      "and poses extrapolated through short losses while they are trusted")
    detector: str = setting(DEFAULT_DETECTOR, choices=tuple(DETECTORS),
                            help="the tag detector: apriltag3 (AprilTag 3, the reference implementation; AprilTag families) "
                                 "or opencv (OpenCV's ArUco module with AprilTag's corner refinement; every family)")
    tag_size_m: float = setting(0.16, min=0.01, max=5.0, unit="m", help="side of the tag's black square")
    tag_margin_cells: float = setting(1.0, min=0.0, max=10.0, help="white paper around the tag, in tag cells")
    table_size_m: tuple[float, float] = setting((1.6, 1.0), min=0.05, max=100.0, unit="m",
                                                help="table top along world x and z, centred on the tag")
    table_albedo: tuple[float, float, float] = setting((0.30, 0.20, 0.12), min=0.0, max=1.0,
                                                       help="diffuse reflectance of the table top (linear RGB)")

    def rules(self) -> str | None:
        if self.near_m > self.far_m:
            return f"far_m = {self.far_m} is below near_m = {self.near_m}: give near_m <= far_m"
        return detector_problem(self.detector, self.tag_family, self.tag_id)


MAP_METHODS = tuple(METHODS)


@dataclass(frozen=True)
class RenderObjectSection:
    """[[render.objects]]: a virtual object standing on the table (the tag's centre is the origin)."""

    kind: str = setting("torus", choices=("torus", "sphere", "sphere_row", "mesh", "disc"),
                        help="torus (normal map, baked AO light map), sphere, sphere_row (exponents 1 to 1280), "
                             "mesh (a triangle mesh file: `mesh`), or disc (a flat disc on the table under the others, "
                             "where their contact shadows show with lighting = inm-...)")
    mesh: Path | None = setting(None, must_exist=True,
                                help="kind = mesh: OBJ, PLY, STL, OFF or glTF file; relative to the scenario, then to assets/")
    position_m: tuple[float, float] = setting((0.0, 0.0), min=-100.0, max=100.0, unit="m",
                                              help="where it stands: world x and z (a row: its centre)")
    size_m: float = setting(0.05, min=0.001, max=10.0, unit="m",
                            help="torus: ring radius; sphere and row: sphere radius; mesh: the largest side of its bounding box; "
                                 "disc: its radius")
    kd: tuple[float, float, float] = setting((0.7, 0.55, 0.4), min=0.0, max=1.0, help="diffuse coefficient k_d (RGB)")
    ks: tuple[float, float, float] = setting((0.2, 0.2, 0.2), min=0.0, max=1.0, help="specular coefficient k_s (RGB)")
    exponent: float = setting(80.0, min=1.0, max=100000.0, help="Phong exponent: the reflection map used (not for a row)")
    method: str = setting("", choices=("",) + MAP_METHODS,
                          help="map method of this object's maps (default \"\": [render] method)")
    material: str = setting("phong", choices=("phong", "ggx"),
                            help="phong (the thesis: kd, ks, exponent) or ggx (metallic-roughness: base_color, metallic, "
                                 "roughness, the specular part from the probe's GGX prefiltered cube map and the split-sum "
                                 "BRDF table; a sphere_row: roughness 0 to 1 along the row)")
    base_color: tuple[float, float, float] = setting((0.8, 0.8, 0.8), min=0.0, max=1.0,
                                                     help="material = ggx: base colour (RGB, linear): the diffuse albedo of a "
                                                          "dielectric, the specular colour F0 of a metal")
    metallic: float = setting(0.0, min=0.0, max=1.0, help="material = ggx: 0 a dielectric (F0 = 0.04), 1 a metal (F0 = base_color)")
    roughness: float = setting(0.5, min=0.0, max=1.0,
                               help="material = ggx: perceptual roughness (alpha = roughness^2; not for a row)")
    normal_map: bool = setting(True, help="torus, and a mesh with texture coordinates: the tangent-space ridges normal map")
    light_map: bool = setting(True, help="torus: its baked ambient-occlusion light map (lighting = lightmap-ao)")
    lighting: str = setting("lightmap-ao",
                            help="ibl (the irradiance map at the perturbed normal), lightmap-ao (torus: that times the "
                                 "ambient-occlusion light map, the thesis; ibl where light_map = false), volume (the "
                                 "scene's irradiance volume, for objects that move: SH bands 0-2 on a grid over the objects, "
                                 "with the other objects' occlusion), or inm-BASIS (any kind that stands still: a directional "
                                 "light map baked from the light with visibility, e.g. inm-modh6, inm-h4, inm-sh9, inm-hl2; see arsim "
                                 "bases compare), or prt-VARIANT (any kind that stands still: precomputed radiance transfer, "
                                 "relit from the light's SH: prt-gs, prt-sep, prt-sep-c, prt-hl2, prt-sal)")
    inm_terms: int = setting(0, min=0, max=9,
                             help="lighting = inm-...: the spec's level of detail, the leading terms summed (1: the constant "
                                  "term, the light map; 4: with the linear ones; 0: all)")
    lightmap_size: int = setting(32, min=1, max=4096,
                                 help="lighting = inm-...: texels of the directional light map's shorter side (a mesh: the most "
                                      "on each side of its unwrapped atlas)")
    prt_order: int = setting(5, min=3, max=10,
                             help="lighting = prt-...: bands of the light's SH the transfer takes (5: bands 0-4)")
    prt_at: str = setting("vertex", choices=("vertex", "texel"),
                          help="lighting = prt-...: the transfer per vertex of the mesh, or per texel of the light map "
                               "(lightmap_size)")
    prt_samples: int = setting(2048, min=64, max=65536,
                               help="lighting = prt-...: directions per point the transfer integrates over (rays cast)")
    prt_bounces: int = setting(0, min=0, max=1,
                               help="lighting = prt-...: 1 adds one bounce of interreflection (the light the objects that "
                                    "stand still and the table send on, grey: the mean of their k_d and of [ar] table_albedo)")
    prt_clusters: int = setting(0, min=0, max=65536,
                                help="lighting = prt-...: CPCA clusters of the transfer matrices (4 principal vectors "
                                     "each; 0: uncompressed)")
    orbit_m: float = setting(0.0, min=0.0, max=100.0, unit="m",
                             help="an object that moves: the radius of the circle it goes round about position_m on the "
                                  "table, counter-clockwise seen from above (0: it stands still); it takes lighting = ibl, "
                                  "lightmap-ao or volume (light maps are baked where objects stand)")
    orbit_period_s: float = setting(8.0, min=0.1, max=3600.0, unit="s", help="orbit_m > 0: the time of one turn")

    def rules(self) -> str | None:
        if self.kind == "mesh" and self.mesh is None:
            return 'kind = "mesh" needs mesh = "FILE" (an OBJ, PLY, STL, OFF or glTF file)'
        return None


@dataclass(frozen=True)
class RenderSection:
    """[render]: the AR session's renderer: the map method, the tone mapper, the virtual objects."""

    method: str = setting("fast", choices=MAP_METHODS, help="map method for the captured probe's maps")
    map_size: int = setting(128, min=8, max=4096, check=map_size_problem,
                            help="N of the N x N irradiance and reflection maps (a power of two)")
    key: float = setting(0.18, min=0.001, max=100.0, help="Reinhard's key a")
    white: float = setting(2.0, min=0.001, max=1e6, help="Reinhard's L_white")
    log_average: bool = setting(False, help="tone-map with Reinhard's log-average luminance instead of the mean (thesis)")
    overlay: bool = setting(False, help="draw the overlay (frame time, map state) at the frames' top left")
    flip_every: int = setting(4, min=1, max=10000,
                              help="the truth frame and its FLIP on every k-th frame (FLIP costs about 1 s of CPU "
                                   "for a whole 640 x 480 frame; 1: every frame)")
    prt_light: str = setting("final", choices=("final", "growing"),
                             help="objects lit by PRT: relit once from the final probe, or (growing) from the probe as the "
                                  "capture grew, about a second of the sweep at a time, replayed over the AR session "
                                  "(step \"relight\" of the profile)")
    methods: tuple[str, ...] = setting((), choices=MAP_METHODS,
                                       help="arsim run: map methods baked and measured besides those the objects use")
    objects: tuple[RenderObjectSection, ...] = subsection(
        RenderObjectSection, array=True,
        default=(RenderObjectSection("sphere_row", position_m=(0.0, -0.14), size_m=0.016, kd=(0.15, 0.15, 0.15),
                                     ks=(0.8, 0.8, 0.8)),
                 RenderObjectSection("torus", position_m=(0.0, 0.0), size_m=0.05)),
        help="the virtual objects")


@dataclass(frozen=True)
class ProfileSection:
    """[profile]: the render loop profiled while it bakes maps tile by tile (`arsim profile`)."""

    budget_ms: float = setting(33.3, min=0.001, max=10000.0, unit="ms", help="frame budget (30 frames/s: 33.3)")
    tile: str = setting("auto", help="tile side baked per frame (a divisor of [render] map_size, e.g. \"64\"), or \"auto\"")
    bake: str = setting("accurate", choices=LOOP_METHODS, help="the method of the maps baked in the loop")
    max_frames: int = setting(20000, min=1, max=10_000_000, unit="frames",
                              help="stop after this many frames even if the bake is not complete")


def _thresholds(higher_is_better: bool = False):
    """check of a [report] threshold pair: (warn, fail), fail beyond warn."""
    def check(value):
        warn, fail = value
        if (fail < warn) if not higher_is_better else (fail > warn):
            return (f"(warn, fail) = ({warn:g}, {fail:g}): fail must be {'at least' if not higher_is_better else 'at most'} "
                    f"warn, e.g. ({warn:g}, {warn * (2 if not higher_is_better else 0.5):g})")
        return None
    return check


@dataclass(frozen=True)
class ReportSection:
    """[report]: the thresholds of the report's verdicts (README: Reading a run), each a pair (warn, fail): a
    headline figure worse than warn warns, worse than fail fails."""

    capture_orientation_deg: tuple[float, float] = setting(
        (0.25, 1.0), min=0.0, max=180.0, unit="degrees", check=_thresholds(),
        help="capture: RMS camera orientation error after drift correction")
    capture_irradiance_pct: tuple[float, float] = setting(
        (1.0, 5.0), min=0.0, max=1000.0, unit="%", check=_thresholds(),
        help="capture: mean error of the irradiance map from the captured probe")
    maps_error_pct: tuple[float, float] = setting(
        (2.0, 10.0), min=0.0, max=1000.0, unit="%", check=_thresholds(),
        help="maps: mean error of [render] method's maps against the true environment's exact maps, worst exponent")
    tracking_rotation_deg: tuple[float, float] = setting(
        (0.5, 2.0), min=0.0, max=180.0, unit="degrees", check=_thresholds(),
        help="tracking: the tag's rotation error, 95th percentile over the frames with the tag in view")
    tracking_position_pct: tuple[float, float] = setting(
        (1.0, 3.0), min=0.0, max=1000.0, unit="% of distance", check=_thresholds(),
        help="tracking: the tag's position error, 95th percentile")
    ar_flip: tuple[float, float] = setting(
        (0.05, 0.15), min=0.0, max=1.0, check=_thresholds(),
        help="AR frames: mean FLIP of the objects against the truth frame over their mask")
    within_budget_pct: tuple[float, float] = setting(
        (95.0, 80.0), min=0.0, max=100.0, unit="%", check=_thresholds(higher_is_better=True),
        help="frame budget: share of frames whose steps 3-7 fit [profile] budget_ms (higher is better: warn below "
             "the first, fail below the second)")


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: one field per TOML section, each a checked, frozen dataclass."""

    run: RunSection = subsection(RunSection, help="run name and seed")
    environment: EnvironmentSection = subsection(EnvironmentSection, help="the true HDR environment")
    device: DeviceSection = subsection(DeviceSection, help="the phone's sensors")
    capture: CaptureSection = subsection(CaptureSection, help="the capture sweep")
    ar: ArSection = subsection(ArSection, help="the AR session's path, tag and table")
    render: RenderSection = subsection(RenderSection, help="the AR session's renderer and virtual objects")
    profile: ProfileSection = subsection(ProfileSection, help="the render loop's profile while baking")
    report: ReportSection = subsection(ReportSection, help="the report's verdict thresholds")
