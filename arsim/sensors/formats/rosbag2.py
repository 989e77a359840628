"""ROS 2 bags (README: Recordings in standard layouts), written and read through rosbags with its ROS 2 Humble
typestore (no ROS install), in MCAP storage (self-describing: each topic's message definition travels with it).

  /cam0/image_raw        sensor_msgs/msg/Image, rgb8 (mono8, bgr8, rgba8, bgra8 read too), header.stamp the frame time
  /cam0/camera_info      sensor_msgs/msg/CameraInfo with each frame: K, plumb_bob D = [k1, k2, 0, 0, 0]
  /cam0/exposure         diagnostic_msgs/msg/DiagnosticArray with each frame (the same header.stamp): one status
                         whose values are exposure_time_ns and iso (ROS has no exposure field; this is arsim's
                         convention, readable by any ROS tool)
  /imu0                  sensor_msgs/msg/Imu: the gyroscope's samples, the accelerometer interpolated to their times
                         (orientation_covariance[0] = -1: no orientation)
  /imu0/mag              sensor_msgs/msg/MagneticField (tesla)
  /tf_static             tf2_msgs/msg/TFMessage: imu0 -> cam0, the camera's rotation in the device frame
  /groundtruth/pose      geometry_msgs/msg/PoseStamped in frame world (when the recording has a ground truth)
  /arsim/...             what ROS messages cannot hold, for an exact round trip: meta (std_msgs/msg/String, JSON),
                         accelerometer (Vector3Stamped, as measured), orientation (QuaternionStamped, the fused
                         orientation), burst/image_raw and burst/exposure (the response burst)

A bag is read into a temporary folder holding its frames as PNG files (removed when the Recording is no longer
used, or at exit); the AR path is a bag of its own in ar/.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import weakref
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.errors import ArsimError
from arsim.core.files import write_bytes_atomic
from arsim.core.png import png_bytes, read_frame
from arsim.sensors.formats.common import (FOREIGN_EXPOSURE_NS, FOREIGN_ISO, exact_rotations, fused_orientation, imu_streams, layout_meta,
                                          merged_imu, recording_of)
from arsim.sensors.imu import SensorStream
from arsim.sensors.recording import _camera_problem, _rotation_problem, Recording

IMAGE, INFO, EXPOSURE = "/cam0/image_raw", "/cam0/camera_info", "/cam0/exposure"
IMU, MAG, TF, TRUTH = "/imu0", "/imu0/mag", "/tf_static", "/groundtruth/pose"
META, ACCEL, ORIENTATION = "/arsim/meta", "/arsim/accelerometer", "/arsim/orientation"
BURST, BURST_EXPOSURE = "/arsim/burst/image_raw", "/arsim/burst/exposure"
BODY, CAMERA, WORLD = "imu0", "cam0", "world"
BAG_NAME = "recording"  # the storage file's name: recording.mcap
TESLA_PER_MICROTESLA = 1e-6


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


class _Messages:
    """The typestore's message classes, and headers from nanoseconds."""

    def __init__(self):
        self.ts = _typestore()
        self.t = self.ts.types

    def header(self, t_ns: int, frame: str):
        sec, nanosec = divmod(int(t_ns), 1_000_000_000)
        return self.t["std_msgs/msg/Header"](stamp=self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame)

    def vector(self, v):
        return self.t["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quaternion(self, q):
        return self.t["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def image(self, t_ns: int, frame: str, rgb: np.ndarray):
        h, w = rgb.shape[:2]
        return self.t["sensor_msgs/msg/Image"](header=self.header(t_ns, frame), height=h, width=w, encoding="rgb8",
                                               is_bigendian=0, step=3 * w, data=np.ascontiguousarray(rgb).reshape(-1))

    def exposure(self, t_ns: int, frame: str, exposure_ns: int, iso: float):
        kv = self.t["diagnostic_msgs/msg/KeyValue"]
        status = self.t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=0, name=f"{frame} exposure", message="", hardware_id=frame,
            values=[kv(key="exposure_time_ns", value=str(int(exposure_ns))), kv(key="iso", value=repr(float(iso)))])
        return self.t["diagnostic_msgs/msg/DiagnosticArray"](header=self.header(t_ns, frame), status=[status])

    def camera_info(self, t_ns: int, cam: dict):
        fx, fy, cx, cy = cam["fx"], cam["fy"], cam["cx"], cam["cy"]
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(t_ns, CAMERA), height=cam["height"], width=cam["width"], distortion_model="plumb_bob",
            d=np.array([cam["k1"], cam["k2"], 0.0, 0.0, 0.0]), k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64),
            r=np.eye(3).reshape(-1), p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64),
            binning_x=0, binning_y=0, roi=roi)


# ----------------------------------------------------------------------------------------------------
# Writing


def write_bag(rec: Recording, out: Path) -> None:
    """rec as a ROS 2 bag in the folder out (made if missing): metadata.yaml and recording.mcap."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # rosbags names the storage file after the bag's folder: made as out/.bag/recording, its files moved up,
    # so that the file's name is the same whatever out is called (and an export is the same bytes)
    scratch = out / ".bag"
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir()
    try:
        _write_bag(rec, scratch / BAG_NAME)
        for f in sorted((scratch / BAG_NAME).iterdir()):
            f.replace(out / f.name)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _write_bag(rec: Recording, out: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    m = _Messages()
    writer = Writer(out, version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        connections = {}

        def put(topic: str, msgtype: str, t_ns: int, msg) -> None:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=m.ts)
            writer.write(connections[topic], max(int(t_ns), 0), m.ts.serialize_cdr(msg, msgtype))

        meta = {k: v for k, v in rec.meta.items() if k != "source_format"}
        t0 = rec.frames[0]["t_ns"] if rec.frames else 0
        put(META, "std_msgs/msg/String", t0, m.t["std_msgs/msg/String"](data=json.dumps(meta)))
        q = Rotation.from_matrix(np.array(rec.meta["camera_to_device"])).as_quat()
        tf = m.t["geometry_msgs/msg/TransformStamped"](
            header=m.header(t0, BODY), child_frame_id=CAMERA,
            transform=m.t["geometry_msgs/msg/Transform"](translation=m.vector([0, 0, 0]), rotation=m.quaternion(q)))
        put(TF, "tf2_msgs/msg/TFMessage", t0, m.t["tf2_msgs/msg/TFMessage"](transforms=[tf]))
        for k, b in enumerate(rec.burst):
            put(BURST, "sensor_msgs/msg/Image", k, m.image(k, CAMERA, read_frame(rec.folder / b["file"])))
            put(BURST_EXPOSURE, "diagnostic_msgs/msg/DiagnosticArray", k, m.exposure(k, CAMERA, b["exposure_ns"], b["iso"]))
        for f in rec.frames:
            t = f["t_ns"]
            put(IMAGE, "sensor_msgs/msg/Image", t, m.image(t, CAMERA, read_frame(rec.folder / f["file"])))
            put(INFO, "sensor_msgs/msg/CameraInfo", t, m.camera_info(t, rec.meta["camera"]))
            put(EXPOSURE, "diagnostic_msgs/msg/DiagnosticArray", t, m.exposure(t, CAMERA, f["exposure_ns"], f["iso"]))
        t, gyro, accel = merged_imu(rec.imu)
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0
        for ti, g, a in zip(t.tolist(), gyro, accel):
            put(IMU, "sensor_msgs/msg/Imu", ti, m.t["sensor_msgs/msg/Imu"](
                header=m.header(ti, BODY), orientation=m.quaternion([0, 0, 0, 1]), orientation_covariance=no_orientation,
                angular_velocity=m.vector(g), angular_velocity_covariance=np.zeros(9),
                linear_acceleration=m.vector(a), linear_acceleration_covariance=np.zeros(9)))
        for ti, v in zip(rec.imu["accelerometer"].t_ns.tolist(), rec.imu["accelerometer"].values):
            put(ACCEL, "geometry_msgs/msg/Vector3Stamped", ti,
                m.t["geometry_msgs/msg/Vector3Stamped"](header=m.header(ti, BODY), vector=m.vector(v)))
        for ti, v in zip(rec.imu["magnetometer"].t_ns.tolist(), rec.imu["magnetometer"].values):
            put(MAG, "sensor_msgs/msg/MagneticField", ti, m.t["sensor_msgs/msg/MagneticField"](
                header=m.header(ti, BODY), magnetic_field=m.vector(v * TESLA_PER_MICROTESLA),
                magnetic_field_covariance=np.zeros(9)))
        for ti, qi in zip(rec.orientation[0].tolist(), rec.orientation[1].as_quat()):
            put(ORIENTATION, "geometry_msgs/msg/QuaternionStamped", ti,
                m.t["geometry_msgs/msg/QuaternionStamped"](header=m.header(ti, WORLD), quaternion=m.quaternion(qi)))
        if rec.groundtruth is not None:
            for ti, p, qi in zip(rec.groundtruth[0].tolist(), rec.groundtruth[1], rec.groundtruth[2].as_quat()):
                pose = m.t["geometry_msgs/msg/Pose"](position=m.t["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                                     orientation=m.quaternion(qi))
                put(TRUTH, "geometry_msgs/msg/PoseStamped", ti,
                    m.t["geometry_msgs/msg/PoseStamped"](header=m.header(ti, WORLD), pose=pose))
    finally:
        writer.close()


# ----------------------------------------------------------------------------------------------------
# Reading


def _stamp(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _rgb(msg, where: str) -> np.ndarray:
    channels = {"rgb8": 3, "bgr8": 3, "mono8": 1, "8UC1": 1, "8UC3": 3, "rgba8": 4, "bgra8": 4}.get(msg.encoding)
    if channels is None:
        raise ArsimError(f"{where}: image encoding {msg.encoding!r}; arsim reads 8-bit images (rgb8, bgr8, mono8, rgba8, bgra8)")
    data = np.asarray(msg.data, dtype=np.uint8)
    if msg.step < msg.width * channels or len(data) < msg.step * msg.height:
        raise ArsimError(f"{where}: an image holds {len(data)} bytes, its header says {msg.height} rows of {msg.step}")
    image = data[:msg.step * msg.height].reshape(msg.height, msg.step)[:, :msg.width * channels].reshape(msg.height, msg.width, channels)
    if channels == 1:
        return np.repeat(image, 3, axis=-1)
    if msg.encoding.startswith("bgr"):
        image = image[..., 2::-1]
    return np.ascontiguousarray(image[..., :3])


def _exposure(msg) -> tuple[int, float] | None:
    for status in msg.status:
        values = {kv.key: kv.value for kv in status.values}
        if "exposure_time_ns" in values:
            try:
                return int(values["exposure_time_ns"]), float(values.get("iso", FOREIGN_ISO))
            except ValueError:
                return None
    return None


def read_bag(path: Path) -> Recording:
    """A ROS 2 bag as a Recording whose frames lie in a temporary folder (removed with the Recording)."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags' errors are many kinds: one line, whatever it was
        raise ArsimError(f"{path}: cannot be read as a ROS 2 bag ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    try:
        return _read(reader, path)
    except ArsimError:
        raise
    except Exception as exc:
        raise ArsimError(f"{path}: a message cannot be read ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    finally:
        reader.close()


def _topic(reader, msgtype: str, preferred: str, exclude: str = "/arsim/") -> str | None:
    topics = sorted(t for t, info in reader.topics.items() if info.msgtype == msgtype and not t.startswith(exclude))
    return preferred if preferred in topics else (topics[0] if topics else None)


def _read(reader, path: Path) -> Recording:
    """Two passes: the small messages first (the camera, the IMU, the extras), then the images one at a time into
    PNG files (a minute's frames decoded at once would be gigabytes)."""
    ts = _typestore()
    image_topic = _topic(reader, "sensor_msgs/msg/Image", IMAGE)
    if image_topic is None:
        raise ArsimError(f"{path}: the bag has no image topic (sensor_msgs/msg/Image); record the camera too")
    images_at = {image_topic, BURST}
    by_topic: dict[str, list] = {}
    small = [c for c in reader.connections if c.topic not in images_at and c.msgtype in ts.types]
    for connection, _, raw in reader.messages(connections=small):
        by_topic.setdefault(connection.topic, []).append(ts.deserialize_cdr(raw, connection.msgtype))
    meta_msgs = by_topic.get(META, [])
    extras = json.loads(meta_msgs[0].data) if meta_msgs else None
    if extras is not None and not isinstance(extras, dict):
        raise ArsimError(f"{path}: {META} holds no JSON object")
    ns = image_topic.rsplit("/", 1)[0]
    info_topic = _topic(reader, "sensor_msgs/msg/CameraInfo", f"{ns}/camera_info")
    if extras is not None and isinstance(extras.get("camera"), dict):
        camera = dict(extras["camera"])
    elif info_topic is not None and by_topic.get(info_topic):
        info = by_topic[info_topic][0]
        camera = {"width": int(info.width), "height": int(info.height), "fx": float(info.k[0]), "fy": float(info.k[4]),
                  "cx": float(info.k[2]), "cy": float(info.k[5]), "k1": float(info.d[0]) if len(info.d) else 0.0,
                  "k2": float(info.d[1]) if len(info.d) > 1 else 0.0, "fps": None}
    else:
        raise ArsimError(f"{path}: the bag has no camera intrinsics (no sensor_msgs/msg/CameraInfo topic beside "
                         f"{image_topic}); add the camera's CameraInfo")
    if problem := _camera_problem({**camera, "fps": camera.get("fps") or 1.0}):
        raise ArsimError(f"{path}: the camera's {problem}")
    exposures = {_stamp(msg): e for msg in by_topic.get(f"{ns}/exposure", []) if (e := _exposure(msg)) is not None}
    burst_exposures = [_exposure(msg) for msg in by_topic.get(BURST_EXPOSURE, [])]

    folder = Path(tempfile.mkdtemp(prefix="arsim-bag-"))
    try:
        (folder / "frames").mkdir()
        frames, burst = [], []
        for connection, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in images_at]):
            msg = ts.deserialize_cdr(raw, connection.msgtype)
            rgb = _rgb(msg, f"{path}: {connection.topic}")
            if rgb.shape[:2] != (camera["height"], camera["width"]):
                raise ArsimError(f"{path}: {connection.topic}: an image is {rgb.shape[1]} x {rgb.shape[0]}, the "
                                 f"camera's are {camera['width']} x {camera['height']}")
            if connection.topic == BURST:
                if len(burst) >= len(burst_exposures) or burst_exposures[len(burst)] is None:
                    raise ArsimError(f"{path}: {BURST} has more images than {BURST_EXPOSURE} has exposures")
                (folder / "burst").mkdir(exist_ok=True)
                name = f"burst/{len(burst):02d}.png"
                exposure_ns, iso = burst_exposures[len(burst)]
                burst.append({"exposure_ns": exposure_ns, "iso": iso, "file": name})
            else:
                t = _stamp(msg)
                if frames and t <= frames[-1]["t_ns"]:
                    raise ArsimError(f"{path}: {image_topic}: message {len(frames) + 1}'s stamp {t} ns is not after the "
                                     f"previous one's {frames[-1]['t_ns']} ns; the frames must be in increasing time order")
                name = f"frames/{len(frames):06d}.png"
                exposure_ns, iso = exposures.get(t, (FOREIGN_EXPOSURE_NS, FOREIGN_ISO))
                frames.append({"t_ns": t, "exposure_ns": exposure_ns, "iso": iso, "file": name})
            write_bytes_atomic(folder / name, png_bytes(rgb))
        if camera.get("fps") is None:
            dt = np.median(np.diff([f["t_ns"] for f in frames])) if len(frames) > 1 else 0
            camera["fps"] = 1e9 / dt if dt > 0 else 30.0
        rec = _recording(reader, by_topic, path, folder, camera, extras, frames, burst)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    weakref.finalize(rec, shutil.rmtree, str(folder), True)  # (also at exit)
    return rec


def _series(path: Path, topic: str, msgs: list) -> np.ndarray:
    t = np.array([_stamp(msg) for msg in msgs], dtype=np.int64)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise ArsimError(f"{path}: {topic}: message {k + 1}'s stamp {t[k]} ns is not after the previous one's "
                         f"{t[k - 1]} ns; the messages must be in increasing time order")
    return t


def _xyz(v) -> list[float]:
    return [v.x, v.y, v.z]


def _recording(reader, by_topic: dict, path: Path, folder: Path, camera: dict, extras: dict | None, frames: list,
               burst: list) -> Recording:
    imu_topic = _topic(reader, "sensor_msgs/msg/Imu", IMU)
    if imu_topic is None:
        raise ArsimError(f"{path}: the bag has no IMU topic (sensor_msgs/msg/Imu); record the IMU too")
    msgs = by_topic[imu_topic]
    t = _series(path, imu_topic, msgs)
    gyro = np.array([_xyz(m.angular_velocity) for m in msgs]).reshape(-1, 3)
    accel = np.array([_xyz(m.linear_acceleration) for m in msgs]).reshape(-1, 3)
    raw = {}
    if by_topic.get(ACCEL):
        raw["accelerometer"] = SensorStream("accelerometer", _series(path, ACCEL, by_topic[ACCEL]),
                                            np.array([_xyz(m.vector) for m in by_topic[ACCEL]]))
    mag_topic = _topic(reader, "sensor_msgs/msg/MagneticField", MAG)
    if mag_topic is not None:
        # tesla back to microtesla at the 9 decimals arsim records (exactly what was written)
        values = [[float(f"{c / TESLA_PER_MICROTESLA:.9f}") for c in _xyz(m.magnetic_field)] for m in by_topic[mag_topic]]
        raw["magnetometer"] = SensorStream("magnetometer", _series(path, mag_topic, by_topic[mag_topic]), np.array(values))
    imu = imu_streams(t, gyro, accel, raw)
    camera_to_device = np.eye(3).tolist()
    for msg in by_topic.get(TF, []):
        for tf in msg.transforms:
            if tf.child_frame_id == CAMERA:
                q = tf.transform.rotation
                camera_to_device = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix().tolist()
    if extras is not None and "camera_to_device" in extras:
        camera_to_device = extras["camera_to_device"]
    if problem := _rotation_problem(camera_to_device):
        raise ArsimError(f"{path}: the camera's rotation in {TF} is {problem}")
    groundtruth = None
    truth_topic = _topic(reader, "geometry_msgs/msg/PoseStamped", TRUTH)
    if truth_topic is not None and len(by_topic[truth_topic]) >= 2:
        msgs = by_topic[truth_topic]
        q = np.array([[m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w] for m in msgs])
        groundtruth = (_series(path, truth_topic, msgs), np.array([_xyz(m.pose.position) for m in msgs]),
                       exact_rotations(q, f"{path}: {truth_topic}"))
    if extras is not None:  # (in the extras' order, so that a second export writes the same JSON)
        meta = extras | {"camera": camera, "camera_to_device": camera_to_device, "source_format": "rosbag2"}
    else:
        meta = layout_meta(camera, camera_to_device, None, frames, imu, "rosbag2")
    if by_topic.get(ORIENTATION):
        msgs = by_topic[ORIENTATION]
        orientation = (_series(path, ORIENTATION, msgs),
                       exact_rotations([[m.quaternion.x, m.quaternion.y, m.quaternion.z, m.quaternion.w] for m in msgs],
                                       f"{path}: {ORIENTATION}"))
    else:
        orientation = fused_orientation(imu, groundtruth, meta["fusion"], f"{path}: {imu_topic}")
    return recording_of(folder, meta, frames, burst, imu, orientation, groundtruth, None)
