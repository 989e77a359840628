"""arsim record: deterministic recordings, read back with checks that explain what is wrong."""

import filecmp

import numpy as np
import pytest

from arsim.core.errors import ArsimError
from arsim.sensors.recording import load_recording
from tests.test_cli import arsim, assert_one_line_error

SHORT = """
[run]
seed = {seed}
[environment]
map = "envmaps/courtyard.exr"
probe_size = 128
[capture]
duration_s = 2.0
[device.camera]
width = 96
height = 72
[ar]
duration_s = 2.0
"""


def _pixel_differences(a, b, names) -> dict:
    """Per differing PNG: how many pixels differ once decoded (0: the same image, other bytes)."""
    from arsim.core.png import read_frame

    return {n: int((read_frame(a / n) != read_frame(b / n)).any(axis=-1).sum()) for n in names if n.endswith(".png")}


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("recordings")
    made = {}
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        scenario = root / f"{name}.toml"
        scenario.write_text(SHORT.format(seed=seed))
        r = arsim("record", scenario, "-o", root / name)
        assert r.returncode == 0, r.stderr
        made[name] = root / name
    return made


def test_same_seed_gives_byte_identical_recordings(recordings):
    a, b, c = recordings["a"], recordings["b"], recordings["c"]
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) > 60
    match, mismatch, errors = filecmp.cmpfiles(a, b, [str(f) for f in files], shallow=False)
    assert not mismatch and not errors, (mismatch, errors, _pixel_differences(a, b, mismatch))
    _, differ, _ = filecmp.cmpfiles(a, c, ["imu.csv", "frames/000010.png"], shallow=False)
    assert differ == ["imu.csv", "frames/000010.png"]


def test_a_recording_reads_back_consistently(recordings):
    rec = load_recording(recordings["a"])
    assert len(rec.frames) == 61 and rec.meta["camera"]["width"] == 96
    assert len(rec.imu["gyroscope"].t_ns) == 401 and len(rec.imu["magnetometer"].t_ns) == 101
    t_truth, positions, truth = rec.groundtruth
    t_fused, fused = rec.orientation
    assert np.array_equal(t_truth, t_fused) and np.abs(positions).max() < 0.1
    exposures = np.array([f["exposure_ns"] for f in rec.frames]) / 1e9
    assert exposures.min() >= 1e-5 and exposures.max() <= 1 / 30 + 1e-9
    assert rec.meta["ar_recording"] == "ar" and rec.meta["segment"] == "capture"
    ar = load_recording(recordings["a"] / "ar")  # the AR path is a recording of its own
    assert ar.meta["segment"] == "ar" and len(ar.frames) == 61 and ar.burst == []
    assert ar.meta["table"]["tag_id"] == 0 and len(ar.meta["table"]["tag_corners_world"]) == 4


def test_info_describes_both_segments(recordings):
    import json

    top = json.loads(arsim("info", recordings["a"], "--json").stdout)
    assert top["segment"] == "capture" and top["ar_recording"].endswith("ar") and top["frames"] == 61
    ar = arsim("info", recordings["a"] / "ar")
    assert ar.returncode == 0 and "tag36h11 id 0, 160 mm" in ar.stdout


def test_damaged_recordings_are_explained(recordings, tmp_path):
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(recordings["a"], broken)
    (broken / "frames" / "000005.png").unlink()
    with pytest.raises(ArsimError, match="listed frames are missing, first frames/000005.png"):
        load_recording(broken)
    assert_one_line_error(arsim("info", broken), "missing")

    backwards = tmp_path / "backwards"
    shutil.copytree(recordings["a"], backwards)
    lines = (backwards / "frames.csv").read_text().splitlines()
    lines[3], lines[4] = lines[4], lines[3]
    (backwards / "frames.csv").write_text("\n".join(lines) + "\n")
    assert_one_line_error(arsim("info", backwards), "go backwards")

    extra = tmp_path / "extra"
    shutil.copytree(recordings["a"], extra)
    shutil.copy(extra / "frames" / "000001.png", extra / "frames" / "999999.png")
    assert_one_line_error(arsim("info", extra), "not in frames.csv")

    nan = tmp_path / "nan"
    shutil.copytree(recordings["a"], nan)
    text = (nan / "imu.csv").read_text().splitlines()
    cells = text[5].split(",")
    cells[2] = "nan"
    text[5] = ",".join(cells)
    (nan / "imu.csv").write_text("\n".join(text) + "\n")
    assert_one_line_error(arsim("info", nan), "NaN")

    version = tmp_path / "version"
    shutil.copytree(recordings["a"], version)
    meta = (version / "meta.json").read_text().replace("arsim-recording/1", "arsim-recording/9")
    (version / "meta.json").write_text(meta)
    assert_one_line_error(arsim("info", version), "arsim-recording/9", "not known")


@pytest.mark.parametrize("toml, fragments", [
    ("[device.gyroscope]\nnoise_densty = 1e-4\n", ["unknown key 'noise_densty'", "did you mean 'noise_density'"]),
    ("[device.accelerometer]\nnoise_density = -1.0\n", ["noise_density = -1.0 is out of range"]),
    ("[ar]\nnear_m = 2.0\nfar_m = 1.0\n", ["far_m = 1.0 is below near_m = 2.0"]),
    ("[[ar.look_away]]\nstart_s = 5.0\nend_s = 4.0\n", ["start_s = 5.0 is not before end_s = 4.0"]),
    ("[ar]\ntag_id = 600\n", ["tag_id = 600 is out of range"]),
    ("[device.camera]\nhfov_deg = 180.0\n", ["hfov_deg = 180.0 is out of range", "179"]),
    ("[device.camera]\nfps = 0\n", ["fps = 0 is out of range"]),
    ("[device.sonar]\nrate_hz = 10.0\n", ["unknown key 'sonar'"]),
])
def test_bad_device_settings_give_one_line(tmp_path, toml, fragments):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(toml)
    assert_one_line_error(arsim("record", scenario, "-o", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out").exists()


def test_camera_misalignment_is_applied_and_recorded(tmp_path):
    from scipy.spatial.transform import Rotation

    scenario = tmp_path / "tilted.toml"
    scenario.write_text(SHORT.format(seed=1) + "[device]\ncamera_misalignment_deg = [0.0, 2.0, 0.0]\n")
    r = arsim("record", scenario, "-o", tmp_path / "rec")
    assert r.returncode == 0, r.stderr
    mount = Rotation.from_matrix(np.array(load_recording(tmp_path / "rec").meta["camera_to_device"]))
    nominal = Rotation.from_matrix(np.diag([1.0, -1.0, -1.0]))
    assert (nominal.inv() * mount).magnitude() == pytest.approx(np.deg2rad(2.0), rel=1e-9)


def test_the_bracketed_burst_brightens_with_exposure(recordings):
    import cv2

    rec = load_recording(recordings["a"])
    assert len(rec.burst) == 13  # the default: half stops over six stops
    products = [b["exposure_ns"] * b["iso"] for b in rec.burst]  # time first, then ISO
    assert all(b / a == pytest.approx(2.0**0.5, rel=1e-3) for a, b in zip(products, products[1:]))
    assert all(b["exposure_ns"] <= round(1e9 / 30) and 100 <= b["iso"] <= 3200 for b in rec.burst)
    frames = [cv2.imread(str(recordings["a"] / b["file"])) for b in rec.burst]
    means = [f.mean() for f in frames]
    assert all(a < b for a, b in zip(means, means[1:]))
    assert means[0] < 60 and means[-1] > 120  # bracketed around the auto-exposure: dark to bright


def test_the_ar_path_shows_the_tag_where_the_truth_says(tmp_path):
    """OpenCV finds the printed tag in the rendered AR frames whenever its corners are in the image,
    and not while the phone looks away."""
    import cv2

    from arsim.evaluate.recording_plots import tag_in_view

    scenario = tmp_path / "ar.toml"
    scenario.write_text('[run]\nseed = 3\n[environment]\nmap = "envmaps/courtyard.exr"\nprobe_size = 128\n'
                        "[capture]\nduration_s = 1.0\n[device.camera]\nwidth = 320\nheight = 240\nfps = 10.0\n"
                        "[ar]\nduration_s = 10.0\ntag_id = 7\n[[ar.look_away]]\nstart_s = 4.0\nend_s = 7.0\n")
    r = arsim("record", scenario, "-o", tmp_path / "rec")
    assert r.returncode == 0, r.stderr
    assert "tag in view" in r.stdout and (tmp_path / "rec" / "plots" / "ar_path.png").exists()
    rec = load_recording(tmp_path / "rec" / "ar")
    seen = tag_in_view(rec)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    found = []
    for frame in rec.frames:
        _, ids, _ = detector.detectMarkers(cv2.imread(str(rec.folder / frame["file"]), cv2.IMREAD_GRAYSCALE))
        found.append(ids is not None and 7 in ids.ravel())
    found = np.array(found)
    assert 0.2 < (~seen).mean() < 0.6  # the look-away window hides it for a while
    assert found[seen].mean() >= 0.9 and not found[~seen].any()


def _meta(folder, change):
    import json

    meta = json.loads((folder / "meta.json").read_text())
    (folder / "meta.json").write_text(json.dumps(change(meta)))


def _csv_line(folder, name, k, change):
    lines = (folder / name).read_text().splitlines()
    lines[k] = change(lines[k])
    (folder / name).write_text("\n".join(lines) + "\n")


def _replace_with_folder(path):
    path.unlink()
    path.mkdir()


MUTATIONS = {  # what an adversarial user did to a recording -> what the one line must say
    "meta is a list": (lambda f: (f / "meta.json").write_text("[1, 2]"), "not an object"),
    "meta lacks seed": (lambda f: _meta(f, lambda m: {k: v for k, v in m.items() if k != "seed"}), "lacks 'seed'"),
    "meta lacks camera": (lambda f: _meta(f, lambda m: {k: v for k, v in m.items() if k != "camera"}), "lacks 'camera'"),
    "the scenario is not text": (lambda f: _meta(f, lambda m: m | {"scenario_toml": 3}), "scenario_toml is not"),
    "seed is a string": (lambda f: _meta(f, lambda m: m | {"seed": "zero"}), "seed is not"),
    "fps is a string": (lambda f: _meta(f, lambda m: m | {"camera": m["camera"] | {"fps": "fast"}}), "camera.fps is 'fast'"),
    "k1 is 3.5": (lambda f: _meta(f, lambda m: m | {"camera": m["camera"] | {"k1": 3.5}}), "camera.k1 = 3.5 is out of range"),
    "mount is not a rotation": (lambda f: _meta(f, lambda m: m | {"camera_to_device": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}),
                                "not a 3 x 3 rotation"),
    "meta not UTF-8": (lambda f: (f / "meta.json").write_bytes(b"\xff\xfe{"), "not valid JSON"),
    "a short CSV row": (lambda f: _csv_line(f, "frames.csv", 3, lambda line: line.rsplit(",", 1)[0]), "line 4 has 3 fields"),
    "a zero quaternion": (lambda f: _csv_line(f, "orientation.csv", 2, lambda line: line.split(",")[0] + ",0,0,0,0"),
                          "line 3 has a zero quaternion"),
    "orientation header only": (lambda f: (f / "orientation.csv").write_text("t_ns,qx,qy,qz,qw\n"), "need at least 2"),
    "imu.csv is a folder": (lambda f: _replace_with_folder(f / "imu.csv"), "not a file"),
    "frames.csv not UTF-8": (lambda f: (f / "frames.csv").write_bytes(b"t_ns,exposure_ns,iso,file\n\xff\xff,1,2,3\n"),
                             "not UTF-8"),
    "an empty frame": (lambda f: (f / "frames" / "000003.png").write_bytes(b""), "000003.png: is not a PNG"),
    "a frame of the wrong size": (lambda f: __import__("cv2").imwrite(str(f / "frames" / "000004.png"),
                                                                      np.zeros((1, 1, 3), np.uint8)),
                                  "000004.png: is 1 x 1, the camera's frames are 96 x 72"),
}


@pytest.mark.parametrize("name", list(MUTATIONS))
def test_a_mutated_recording_is_refused_in_one_line_naming_the_file(recordings, tmp_path, capsys, name):
    import shutil

    import arsim.cli as cli

    mutate, fragment = MUTATIONS[name]
    rec = tmp_path / "rec"
    shutil.copytree(recordings["a"], rec, ignore=shutil.ignore_patterns("ar", "plots"))
    mutate(rec)
    status = cli.main(["info", str(rec)])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and captured.out == "", captured.err
    assert fragment in lines[0] and str(rec) in lines[0], lines[0]


def test_info_decodes_every_frame(recordings, tmp_path):
    import shutil

    # a frame whose header is intact but whose pixels are cut off: only decoding it finds that
    rec = tmp_path / "rec"
    shutil.copytree(recordings["a"], rec, ignore=shutil.ignore_patterns("ar", "plots"))
    data = (rec / "frames" / "000002.png").read_bytes()
    (rec / "frames" / "000002.png").write_bytes(data[:40])
    load_recording(rec)  # the header alone is read at load
    assert_one_line_error(arsim("info", rec), "000002.png", "is truncated")


def test_recording_again_over_a_killed_recording_replaces_it(recordings, tmp_path):
    import shutil

    # a record killed mid-write leaves an atomic writer's temp frame and frames of its own; the next record
    # into the folder must neither fail on them nor keep them
    rec = tmp_path / "rec"
    shutil.copytree(recordings["a"], rec)
    (rec / "frames" / ".000007.k2j3h4.tmp.png").write_bytes(b"\x89PNG half")
    shutil.copy(rec / "frames" / "000001.png", rec / "frames" / "999999.png")
    (tmp_path / "a.toml").write_text(SHORT.format(seed=1))
    r = arsim("record", tmp_path / "a.toml", "-o", rec)
    assert r.returncode == 0, r.stderr
    assert not (rec / "frames" / ".000007.k2j3h4.tmp.png").exists() and not (rec / "frames" / "999999.png").exists()
    assert filecmp.cmp(rec / "frames.csv", recordings["a"] / "frames.csv", shallow=False)
    load_recording(rec)
    # a temp frame alone (the writer killed after the recording was complete) is not a frame of the recording
    (rec / "frames" / ".000003.abcd.tmp.png").write_bytes(b"")
    load_recording(rec)


def test_a_recording_names_the_bundled_assets_by_name_so_that_it_loads_with_arsim_elsewhere(tmp_path):
    """The scenario a recording keeps (meta.json) names the bundled environment as a scenario does
    ("envmaps/...", resolved against the assets wherever arsim is installed), not by this install's
    absolute path; and it loads back to the same file."""
    import json

    from arsim.capture.pipeline import recording_scenario
    from arsim.core.assets import assets_dir
    from arsim.sensors.recording import load_recording
    from tests.test_cli import arsim

    (tmp_path / "s.toml").write_text('[environment]\nmap = "envmaps/courtyard.exr"\nprobe_size = 64\n[capture]\n'
                                     'duration_s = 1.0\n[device.camera]\nwidth = 64\nheight = 48\n[ar]\nenabled = false\n')
    r = arsim("record", tmp_path / "s.toml", "-o", tmp_path / "rec")
    assert r.returncode == 0, r.stderr
    text = json.loads((tmp_path / "rec" / "meta.json").read_text())["scenario_toml"]
    assert 'map = "envmaps/courtyard.exr"' in text and str(assets_dir().resolve()) not in text
    rec = load_recording(tmp_path / "rec")
    assert recording_scenario(rec).environment.map == (assets_dir() / "envmaps" / "courtyard.exr").resolve()


def test_a_recording_without_its_images_says_so_and_how_to_make_them_again(recordings, tmp_path):
    """sensors.recording.leave_out_images (what `arsim run` does to its recording): the images go, the small files
    stay, each segment says what it lacks, a load names the scenario to record again; a note that cannot be
    read still says the images were left out."""
    import json
    import shutil

    from arsim.sensors.recording import (NOT_KEPT, images_digest, leave_out_images, recording_image_paths,
                                         recording_images)

    run = tmp_path / "run"
    shutil.copytree(recordings["a"], run / "recording")
    hashes = recording_images(run / "recording")
    paths = recording_image_paths(run / "recording")
    assert sorted(hashes) == sorted(paths) and "burst/00.png" in paths and "ar/frames/000000.png" in paths
    total = leave_out_images(run / "recording", hashes, {"recording_key": "k", "recording_content": "c",
                                                         "scenario": "../scenario.toml"})
    assert total["files"] == len(paths) and total["sha256"] == images_digest(hashes)
    assert total["bytes"] == sum((recordings["a"] / rel).stat().st_size for rel in paths)
    assert not (run / "recording" / "frames").exists() and not (run / "recording" / "ar" / "burst").exists()
    for name in ("meta.json", "frames.csv", "imu.csv", "groundtruth.csv", "ar/orientation.csv"):
        assert filecmp.cmp(run / "recording" / name, recordings["a"] / name, shallow=False), name
    ar = json.loads((run / "recording" / "ar" / NOT_KEPT).read_text())
    assert ar["scenario"] == "../../scenario.toml" and ar["recording_key"] == "k"
    assert ar["files"] == len([p for p in paths if p.startswith("ar/")])
    with pytest.raises(ArsimError, match=r"its \d+ frame images .* were not kept by `arsim run`.*"
                                         rf"arsim record {run / 'scenario.toml'} -o REC"):
        load_recording(run / "recording")
    with pytest.raises(ArsimError, match=rf"arsim record {run / 'scenario.toml'} -o REC"):
        load_recording(run / "recording" / "ar")
    (run / "recording" / NOT_KEPT).write_text("{")
    assert_one_line_error(arsim("info", run / "recording"), "frame images were left out", "record the scenario again")
    # the images put back (made again, or copied from the cache): the recording loads as it did
    shutil.copytree(recordings["a"] / "frames", run / "recording" / "frames")
    shutil.copytree(recordings["a"] / "burst", run / "recording" / "burst")
    assert len(load_recording(run / "recording").frames) == len(load_recording(recordings["a"]).frames)


def test_a_compact_recording_holds_the_same_pixels_and_renders_byte_identical_frames(recordings, tmp_path):
    """`arsim record --compact`: each segment's frames in one lossless FFV1 video, every other file the PNG
    recording's; deterministic; `arsim render` of it gives the PNG recording's frames byte for byte; a damaged
    video is refused in one line."""
    import shutil

    from arsim.core.png import read_frames

    (tmp_path / "a.toml").write_text(SHORT.format(seed=1))
    for name in ("c1", "c2"):
        r = arsim("record", tmp_path / "a.toml", "-o", tmp_path / name, "--compact")
        assert r.returncode == 0, r.stderr
    png, compact = recordings["a"], tmp_path / "c1"
    assert not (compact / "frames").exists() and (compact / "ar" / "frames.mkv").is_file()
    def contents(root):
        return {q.relative_to(root).as_posix(): q.read_bytes() for q in root.rglob("*") if q.is_file()}

    # the same seed, the same bytes (the videos and their checksums too)
    assert contents(compact) == contents(tmp_path / "c2") and "ar/frames.mkv.sha256" in contents(compact)
    for segment in ("", "ar"):
        a, b = load_recording(png / segment), load_recording(compact / segment)
        assert [f["file"] for f in b.frames] == [f"frames.mkv#{k:06d}" for k in range(len(a.frames))]
        assert [{k: v for k, v in f.items() if k != "file"} for f in a.frames] == \
               [{k: v for k, v in f.items() if k != "file"} for f in b.frames]
        decoded = zip(read_frames(a.folder / f["file"] for f in a.frames), read_frames(b.folder / f["file"] for f in b.frames))
        assert all(np.array_equal(x, y) for x, y in decoded)
        for name in ("meta.json", "imu.csv", "orientation.csv", "groundtruth.csv", "burst.csv"):
            assert filecmp.cmp(png / segment / name, compact / segment / name, shallow=False), name
    size = sum(p.stat().st_size for p in (png / "frames").iterdir())
    assert (compact / "frames.mkv").stat().st_size < size
    for name, rec in (("png", png), ("compact", compact)):
        r = arsim("render", rec, "-o", tmp_path / f"render_{name}")
        assert r.returncode == 0, r.stderr
    frames = sorted(p.relative_to(tmp_path / "render_png" / "frames").as_posix() for p in (tmp_path / "render_png" / "frames").rglob("*.png"))
    assert frames and frames == sorted(p.relative_to(tmp_path / "render_compact" / "frames").as_posix()
                                       for p in (tmp_path / "render_compact" / "frames").rglob("*.png"))
    for name in [*(f"frames/{f}" for f in frames), "session.mp4"]:
        assert (tmp_path / "render_png" / name).read_bytes() == (tmp_path / "render_compact" / name).read_bytes(), name
    # exported to EuRoC's layout (a PNG per frame): the PNG recording's export, byte for byte
    for name, rec in (("png", png), ("compact", compact)):
        assert arsim("export", rec, "--format", "euroc", "-o", tmp_path / f"euroc_{name}").returncode == 0
    exported = contents(tmp_path / "euroc_png" / "mav0" / "cam0" / "data")
    assert exported == contents(tmp_path / "euroc_compact" / "mav0" / "cam0" / "data")
    assert len(exported) == len(load_recording(png).frames)
    # a byte changed in a video: refused in one line (FFV1's decoder alone would conceal it)
    damaged = tmp_path / "damaged"
    shutil.copytree(compact, damaged)
    data = bytearray((damaged / "ar" / "frames.mkv").read_bytes())
    data[len(data) // 2] ^= 1
    (damaged / "ar" / "frames.mkv").write_bytes(bytes(data))
    assert_one_line_error(arsim("info", damaged / "ar"), "frames.mkv: is damaged", "record again")
    (damaged / "frames.mkv").write_bytes((damaged / "frames.mkv").read_bytes()[:1000])
    assert_one_line_error(arsim("info", damaged), "frames.mkv")
