"""The pinned conventions of arsim, in one place (README: Conventions).

World: right-handed, metres, +y up. Directions are unit 3-vectors in the last axis of an array.

Angle map (thesis Alg. 2.2 / 2.4, Kan's orientation): N x N, row 0 = top row of the file.
    texel centre     s = (col + 0.5) / N,  t = 1 - (row + 0.5) / N
    direction -> st  s = 0.5 + d_x r / 2,  t = 0.5 + d_y r / 2,  r = acos(d_z) / (pi sqrt(d_x^2 + d_y^2))
so the centre is +z, right is +x, up is +y and the rim circle is -z; texels outside the disk are 0.

Equirect (lat-long): W x H, W = 2H, row 0 = top.
    u = (col + 0.5) / W,  v = (row + 0.5) / H,  theta = pi v,  phi = 2 pi u
    d = (sin theta sin phi, cos theta, -sin theta cos phi)
The centre column looks along +z.

Texture (the objects' normal, light and directional light maps): H x W, row 0 = top = v 1.
    texel centre     u = (col + 0.5) / W,  v = (H - 1 - row + 0.5) / H

Camera: OpenCV pinhole (x right, y down, z forward) everywhere but inside render/, which converts with
the helpers at the end of this module. Rotations: scipy.spatial.transform.Rotation, quaternions (x, y, z, w).
"""

from __future__ import annotations

import functools

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "ANGLEMAP_RIM_ST",
    "CameraIntrinsics",
    "OPENCV_TO_OPENGL",
    "CUBE_FACES",
    "CUBE_FACE_NAMES",
    "CUBE_FACE_SUFFIXES",
    "angle_between",
    "anglemap_directions",
    "anglemap_disk_mask",
    "anglemap_radius",
    "anglemap_solid_angles",
    "anglemap_st_to_pixel",
    "anglemap_texel_st",
    "cube_directions",
    "cube_face_st",
    "cube_solid_angles",
    "cube_texels",
    "direction_to_anglemap_st",
    "anglemap_st_to_direction",
    "direction_to_equirect_uv",
    "equirect_uv_to_direction",
    "equirect_directions",
    "equirect_solid_angles",
    "equirect_texel_uv",
    "equirect_uv_to_pixel",
    "gl_projection_from_intrinsics",
    "gl_view_from_opencv_pose",
    "normalize",
    "texture_texel_uv",
    "yaw_rotation",
]

# Alg. 2.2 line 10: where the direction is exactly -z the azimuth is undefined; any point of the rim
# circle is correct, and the thesis returns the top of the rim.
ANGLEMAP_RIM_ST = (0.5, 1.0)


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis (zero vectors stay zero instead of becoming NaN)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians between direction arrays, accurate also for tiny and near-pi angles."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.sum(a * b, axis=-1))


# ---------------------------------------------------------------------------------------------------
# Angle map


def direction_to_anglemap_st(d: np.ndarray) -> np.ndarray:
    """Texture coordinates (s, t) of unit directions d (..., 3) in the angle map (thesis Alg. 2.2).

    The angle from +z is taken as atan2(sqrt(d_x^2 + d_y^2), d_z), equal to acos(d_z) for unit d but
    accurate next to -z, where acos loses half the digits. The thesis's guard (line 4) returns the rim
    point (0.5, 1) both for -z and for +z; for +z that is a typo (the limit there is the centre), so
    +z maps to (0.5, 0.5) here and only -z gets the rim point.
    """
    d = np.asarray(d, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    b = np.hypot(x, y)
    a = np.arctan2(b, z)
    # r = a / (pi b) as (x / b) (a / pi): |x / b| <= 1, so a subnormal b cannot overflow r into inf * 0.
    safe_b = np.where(b > 0, b, 1.0)
    s = 0.5 + 0.5 * np.where(b > 0, x / safe_b, 0.0) * (a / np.pi)
    t = 0.5 + 0.5 * np.where(b > 0, y / safe_b, 0.0) * (a / np.pi)
    at_minus_z = (b == 0) & (z < 0)
    s = np.where(at_minus_z, ANGLEMAP_RIM_ST[0], s)
    t = np.where(at_minus_z, ANGLEMAP_RIM_ST[1], t)
    return np.stack([s, t], axis=-1)


def anglemap_radius(st: np.ndarray) -> np.ndarray:
    """Disk radius rho = sqrt((2s-1)^2 + (2t-1)^2) of texture coordinates (..., 2); 1 is the rim (-z)."""
    st = np.asarray(st, dtype=np.float64)
    return np.hypot(2.0 * st[..., 0] - 1.0, 2.0 * st[..., 1] - 1.0)


def anglemap_st_to_direction(st: np.ndarray) -> np.ndarray:
    """Unit direction of angle-map texture coordinates (..., 2): the exact inverse of Alg. 2.2 (Alg. 2.4).

    rho is the angle from +z divided by pi. Points outside the disk (rho > 1) are clamped to the rim.
    """
    st = np.asarray(st, dtype=np.float64)
    sp = 2.0 * st[..., 0] - 1.0
    tp = 2.0 * st[..., 1] - 1.0
    rho = np.hypot(sp, tp)
    angle = np.pi * np.minimum(rho, 1.0)
    safe_rho = np.where(rho > 0, rho, 1.0)
    sin_a = np.sin(angle)
    x = np.where(rho > 0, sin_a * sp / safe_rho, 0.0)
    y = np.where(rho > 0, sin_a * tp / safe_rho, 0.0)
    return np.stack([x, y, np.cos(angle)], axis=-1)


def anglemap_texel_st(n: int) -> np.ndarray:
    """Texture coordinates of every texel centre of an N x N angle map, shape (N, N, 2), [row, col]."""
    c = (np.arange(n, dtype=np.float64) + 0.5) / n
    s = np.broadcast_to(c[None, :], (n, n))
    t = np.broadcast_to(1.0 - c[:, None], (n, n))
    return np.stack([s, t], axis=-1)


def anglemap_st_to_pixel(st: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (row, col) pixel coordinates of texture coordinates, texel centres at integers."""
    st = np.asarray(st, dtype=np.float64)
    col = st[..., 0] * n - 0.5
    row = (1.0 - st[..., 1]) * n - 0.5
    return row, col


@functools.lru_cache(maxsize=16)
def _texel_radius(n: int) -> np.ndarray:
    """anglemap_radius of every texel centre of an N x N angle map, computed once per N (read-only)."""
    rho = anglemap_radius(anglemap_texel_st(n))
    rho.flags.writeable = False
    return rho


def anglemap_disk_mask(n: int) -> np.ndarray:
    """True for texels whose centre lies inside the unit disk (rho < 1), shape (N, N)."""
    return _texel_radius(n) < 1.0


def anglemap_directions(n: int) -> np.ndarray:
    """Direction of every texel centre, shape (N, N, 3); texels outside the disk get the rim direction."""
    return anglemap_st_to_direction(anglemap_texel_st(n))


def anglemap_solid_angles(n: int) -> np.ndarray:
    """Solid angle of every texel, (2 pi / N)^2 sinc(pi rho), 0 outside the disk; sums to ~4 pi."""
    rho = _texel_radius(n)
    w = (2.0 * np.pi / n) ** 2 * np.sinc(rho)  # numpy's sinc(x) is sin(pi x) / (pi x)
    return np.where(rho < 1.0, w, 0.0)


# ---------------------------------------------------------------------------------------------------
# Equirect


def equirect_uv_to_direction(uv: np.ndarray) -> np.ndarray:
    """Unit direction of equirect coordinates (..., 2) with u, v in [0, 1]."""
    uv = np.asarray(uv, dtype=np.float64)
    theta = np.pi * uv[..., 1]
    phi = 2.0 * np.pi * uv[..., 0]
    st = np.sin(theta)
    return np.stack([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)], axis=-1)


def direction_to_equirect_uv(d: np.ndarray) -> np.ndarray:
    """Equirect coordinates (u, v) in [0, 1) x [0, 1] of unit directions (..., 3); u = 0 at the poles."""
    d = np.asarray(d, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    theta = np.arctan2(np.hypot(x, z), y)
    phi = np.mod(np.arctan2(x, -z), 2.0 * np.pi)
    u = phi / (2.0 * np.pi)
    u = np.where(u >= 1.0, 0.0, u)  # mod can round up to exactly 2 pi
    return np.stack([u, theta / np.pi], axis=-1)


def equirect_uv_to_pixel(uv: np.ndarray, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (row, col) pixel coordinates in a 2H x H equirect, texel centres at integers."""
    uv = np.asarray(uv, dtype=np.float64)
    return uv[..., 1] * height - 0.5, uv[..., 0] * 2 * height - 0.5


def equirect_texel_uv(height: int) -> np.ndarray:
    """Coordinates (u, v) of every texel centre of a 2H x H equirect, shape (H, 2H, 2), [row, col]."""
    u = (np.arange(2 * height, dtype=np.float64) + 0.5) / (2 * height)
    v = (np.arange(height, dtype=np.float64) + 0.5) / height
    return np.stack(np.broadcast_arrays(u[None, :], v[:, None]), axis=-1)


def texture_texel_uv(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v), each (H, W): the texture coordinates of an H x W texture's texel centres, row 0 at v = 1."""
    v, u = np.meshgrid((height - 1 - np.arange(height) + 0.5) / height, (np.arange(width) + 0.5) / width, indexing="ij")
    return u, v


def equirect_directions(height: int) -> np.ndarray:
    """Direction of every texel centre of a 2H x H equirect, shape (H, 2H, 3)."""
    return equirect_uv_to_direction(equirect_texel_uv(height))


def equirect_solid_angles(height: int) -> np.ndarray:
    """Exact solid angle of every texel of a 2H x H equirect, (2 pi / W)(cos theta0 - cos theta1)."""
    edges = np.cos(np.pi * np.arange(height + 1, dtype=np.float64) / height)
    per_row = (2.0 * np.pi / (2 * height)) * (edges[:-1] - edges[1:])
    return np.broadcast_to(per_row[:, None], (height, 2 * height)).copy()


def yaw_rotation(degrees: float) -> Rotation:
    """Rotation about world +y (up) by the given angle, counter-clockwise seen from above."""
    return Rotation.from_rotvec([0.0, np.deg2rad(degrees), 0.0])


# ---------------------------------------------------------------------------------------------------
# Cube maps: OpenGL's and Vulkan's (and KTX2's) convention


# OpenGL's cube-map faces in their order +X, -X, +Y, -Y, +Z, -Z: per face its major axis and the axes s and t
# run along (GL spec, table 8.19); a face's row r, column c is at s = (c + 0.5) / N, t = (r + 0.5) / N, row 0 first
CUBE_FACES = (((1, 0, 0), (0, 0, -1), (0, -1, 0)), ((-1, 0, 0), (0, 0, 1), (0, -1, 0)),
              ((0, 1, 0), (1, 0, 0), (0, 0, 1)), ((0, -1, 0), (1, 0, 0), (0, 0, -1)),
              ((0, 0, 1), (1, 0, 0), (0, -1, 0)), ((0, 0, -1), (-1, 0, 0), (0, -1, 0)))


def cube_directions(size: int) -> np.ndarray:
    """(6, size, size, 3) unit directions at the texel centres of the six faces: row r, column c at
    s = (c + 0.5) / size, t = (r + 0.5) / size."""
    st = (np.arange(size) + 0.5) / size * 2 - 1
    t, s = np.meshgrid(st, st, indexing="ij")
    faces = [np.asarray(major) + s[..., None] * np.asarray(sa) + t[..., None] * np.asarray(ta) for major, sa, ta in CUBE_FACES]
    return normalize(np.stack(faces).astype(np.float64))


def cube_solid_angles(size: int) -> np.ndarray:
    """(size, size) the solid angle of a face's texels (the same on every face; they sum to 4 pi / 6)."""
    edges = np.linspace(-1.0, 1.0, size + 1)

    def corner(x, y):  # the solid angle of the face's part from its centre to (x, y)
        return np.arctan2(x * y, np.sqrt(x * x + y * y + 1))

    x0, y0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    x1, y1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    return corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0)


def cube_face_st(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face, s, t) of unit directions (K, 3): the face each falls on (its major axis) and its coordinates
    s, t in [-1, 1] on that face (CUBE_FACES)."""
    d = np.asarray(directions, dtype=np.float64)
    axis = np.argmax(np.abs(d), axis=1)
    face = 2 * axis + (d[np.arange(len(d)), axis] < 0)
    table = np.array(CUBE_FACES, dtype=np.float64)  # (6, 3 vectors, 3)
    major = np.abs(d[np.arange(len(d)), axis])
    s = np.einsum("kj,kj->k", d, table[face, 1]) / major
    t = np.einsum("kj,kj->k", d, table[face, 2]) / major
    return face, s, t


def cube_texels(directions: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face, row, col) of the cube texel each unit direction (K, 3) falls in."""
    face, s, t = cube_face_st(directions)
    col = np.clip(((s + 1) / 2 * size).astype(int), 0, size - 1)
    row = np.clip(((t + 1) / 2 * size).astype(int), 0, size - 1)
    return face, row, col


CUBE_FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
CUBE_FACE_SUFFIXES = ("px", "nx", "py", "ny", "pz", "nz")  # file names of faces, as three.js and most tools write them


# ---------------------------------------------------------------------------------------------------
# Camera: OpenCV pinhole, and the conversion to OpenGL used inside render/

# Camera axes: OpenCV (x right, y down, z forward) -> OpenGL (x right, y up, z backward).
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0])


def is_map_size(n: int) -> bool:
    """Map and probe sides are powers of two from 8 up (the MIP chains and the tiles halve them)."""
    return n >= 8 and n & (n - 1) == 0


def map_size_problem(n: int) -> str | None:
    """What is wrong with a map side, and how to fix it (None: nothing)."""
    return None if is_map_size(n) else "is not a power of two from 8 up: give 64, 128, 256, 512, ..."


@dataclass(frozen=True)
class CameraIntrinsics:
    """OpenCV pinhole intrinsics with optional radial distortion (OpenCV's k1, k2); pixel (0, 0) is the
    centre of the top-left pixel."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float, k1: float = 0.0, k2: float = 0.0) -> CameraIntrinsics:
        """Square pixels, principal point at the image centre, horizontal field of view in degrees
        (of the undistorted pinhole)."""
        f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2.0)
        return cls(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0, k1, k2)

    @property
    def matrix(self) -> np.ndarray:
        """The 3 x 3 camera matrix K as cv2.solvePnP and cv2.projectPoints take it."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> np.ndarray:
        """OpenCV distortion coefficients (k1, k2, p1, p2)."""
        return np.array([self.k1, self.k2, 0.0, 0.0])

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) of camera-frame points (..., 3) with z > 0 (distortion applied)."""
        p = np.asarray(points_cam, dtype=np.float64)
        x, y = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
        r2 = x * x + y * y
        radial = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        return np.stack([self.fx * x * radial + self.cx, self.fy * y * radial + self.cy], axis=-1)

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """Unit bearing vectors (..., 3) in the camera frame of pixel coordinates (..., 2)."""
        px = np.asarray(pixels, dtype=np.float64)
        if self.k1 or self.k2:  # OpenCV's iterative undistortion
            flat = cv2.undistortPoints(px.reshape(-1, 1, 2), self.matrix, self.distortion,
                                       criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12))
            x, y = flat[:, 0, 0].reshape(px.shape[:-1]), flat[:, 0, 1].reshape(px.shape[:-1])
        else:
            x = (px[..., 0] - self.cx) / self.fx
            y = (px[..., 1] - self.cy) / self.fy
        return normalize(np.stack([x, y, np.ones_like(x)], axis=-1))


def gl_projection_from_intrinsics(k: CameraIntrinsics, near: float, far: float) -> np.ndarray:
    """OpenGL projection matrix (4 x 4, row-major maths) that puts a point exactly where K does
    (without distortion, which a projection matrix cannot express).

    A camera-frame point that OpenCV projects to pixel (u, v) lands, after the OpenCV -> OpenGL axis flip,
    at window coordinates (u + 0.5, H - v - 0.5): GL pixel centres sit at half-integers, origin bottom left.
    """
    w, h = k.width, k.height
    p = np.zeros((4, 4))
    p[0, 0] = 2.0 * k.fx / w
    p[0, 2] = 1.0 - 2.0 * (k.cx + 0.5) / w
    p[1, 1] = 2.0 * k.fy / h
    p[1, 2] = 2.0 * (k.cy + 0.5) / h - 1.0
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2.0 * far * near / (far - near)
    p[3, 2] = -1.0
    return p


def gl_view_from_opencv_pose(rotation: Rotation, translation: np.ndarray) -> np.ndarray:
    """OpenGL view matrix (4 x 4) from an OpenCV world-to-camera pose (x_cam = R x_world + t)."""
    view = np.eye(4)
    view[:3, :3] = OPENCV_TO_OPENGL @ rotation.as_matrix()
    view[:3, 3] = OPENCV_TO_OPENGL @ np.asarray(translation, dtype=np.float64)
    return view
