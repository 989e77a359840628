"""`arsim render` end to end on a short AR path: frames, video and metrics written; lit by the true
environment (--env), the AR frames equal the truth frames (FLIP 0 by construction); lost frames draw
nothing; a scenario without an AR path is refused in one line."""

import json

import cv2
import numpy as np
import trimesh

from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error

SESSION = """
[run]
seed = 4
[environment]
map = "{env}"
probe_size = 128
[capture]
duration_s = 1.0
[device.camera]
width = 320
height = 240
fps = 10.0
[ar]
duration_s = 5.0
near_m = 0.3
far_m = 0.6
[[ar.look_away]]
start_s = 2.0
end_s = 3.5
[render]
flip_every = 1
[[render.objects]]
kind = "torus"
[[render.objects]]
kind = "mesh"
mesh = "cube.obj"
position_m = [0.12, 0.0]
size_m = 0.05
method = "mipmap"
"""


def test_render_with_the_true_environment_matches_the_truth_frames(tmp_path):
    (tmp_path / "s.toml").write_text(SESSION.format(env=ENVMAPS[1].as_posix()))
    trimesh.creation.box().export(tmp_path / "cube.obj")  # a mesh file, lit by another method's maps
    r = arsim("render", tmp_path / "s.toml", "-o", tmp_path / "out", "--env", ENVMAPS[1], "--map-size", "64", "--log-average",
              "--overlay")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out"
    m = json.loads((out / "metrics.json").read_text())
    for key in ("tracking_rot_err_deg_p95", "tracking_trans_err_pct_p95", "frames_total", "frames_lost", "flip_mean", "step_ms"):
        assert key in m, key
    assert m["frames_total"] == 51 and 0 < m["frames_lost"] < m["frames_total"]
    assert m["flip_mean"] == 0.0  # the same maps on both sides (the overlay's box left out)
    lost = [k for k, f in enumerate(m["flip_per_frame"]) if f is None]
    assert len(lost) == m["frames_lost"]  # a lost frame draws no object, so nothing is compared
    assert set(m["step_ms"]) >= {"track", "background", "objects", "tone_mapping", "overlay"}
    assert m["methods"] == {"fast": [1.0, 80.0], "mipmap": [1.0, 80.0]}
    frames = sorted((out / "frames").glob("*.png"))
    assert len(frames) == 4
    video = cv2.VideoCapture(str(out / "session.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 51
    # a frame where the tag was found shows objects over the camera image: it differs from the recording
    drawn = next(k for k, f in enumerate(m["flip_per_frame"]) if f is not None and (out / "frames" / f"{k:06d}.png").exists())
    rendered = cv2.imread(str(out / "frames" / f"{drawn:06d}.png"))
    camera = cv2.imread(str(out / "recording" / "ar" / "frames" / f"{drawn:06d}.png"))
    assert np.mean(np.any(rendered != camera, axis=-1)) > 0.01


def test_render_refuses_bad_input_in_one_line(tmp_path):
    (tmp_path / "s.toml").write_text("[ar]\nenabled = false\n")
    assert_one_line_error(arsim("render", tmp_path / "s.toml", "-o", tmp_path / "out"), "enabled = false")
    assert_one_line_error(arsim("render", "-o", tmp_path / "out", "--key", "0"), "--key")
    assert_one_line_error(arsim("render", "-o", tmp_path / "out", "--every", "0"), "--every")
    assert_one_line_error(arsim("render", "-o", tmp_path / "out", "--map-size", "0"), "size")
    (tmp_path / "exponent.toml").write_text('[[render.objects]]\nkind = "sphere"\nexponent = 0.0\n')
    assert_one_line_error(arsim("render", tmp_path / "exponent.toml", "-o", tmp_path / "out"), "exponent")
    (tmp_path / "width.toml").write_text("[device.camera]\nwidth = 0\n")  # a frame resolution of 0
    assert_one_line_error(arsim("render", tmp_path / "width.toml", "-o", tmp_path / "out"), "width = 0")
    (tmp_path / "size.toml").write_text("[render]\nmap_size = 100\n")
    assert_one_line_error(arsim("render", tmp_path / "size.toml", "-o", tmp_path / "out"), "map_size")
    # a mesh file that cannot be read, one that is not there, and a mesh object without its file
    (tmp_path / "broken.ply").write_bytes(b"\x00\x01 not a mesh")
    for mesh, fragment in (("broken.ply", "cannot read the mesh"), ("missing.obj", "no such file")):
        (tmp_path / "mesh.toml").write_text(f'[[render.objects]]\nkind = "mesh"\nmesh = "{mesh}"\n')
        assert_one_line_error(arsim("render", tmp_path / "mesh.toml", "-o", tmp_path / "out"), fragment)
    (tmp_path / "nomesh.toml").write_text('[[render.objects]]\nkind = "mesh"\n')
    assert_one_line_error(arsim("render", tmp_path / "nomesh.toml", "-o", tmp_path / "out"), "needs mesh")
    # maps baked before that lack the chosen method, or an exponent; a folder that is no bake
    bake = tmp_path / "fast"
    assert arsim("bake", ENVMAPS[1], "-o", bake, "--method", "fast", "--size", "16", "--spec", "1,80").returncode == 0
    assert_one_line_error(arsim("render", "-o", tmp_path / "out", "--maps", bake, "--method", "sh"), "no sh maps")
    (tmp_path / "sphere.toml").write_text('[[render.objects]]\nkind = "sphere"\nexponent = 40.0\n')
    assert_one_line_error(arsim("render", tmp_path / "sphere.toml", "-o", tmp_path / "out", "--maps", bake), "exponent 40")
    assert_one_line_error(arsim("render", "-o", tmp_path / "out", "--maps", tmp_path), "no bake.json")
    assert not (tmp_path / "out").exists()
