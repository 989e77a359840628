"""The virtual objects the AR session places on the tag (thesis figure 5.3 and 5.1): a row of spheres
with Phong exponents from 1 to 1280, a torus, non-convex, with a tangent-space normal map and an
ambient-occlusion light map that arsim bakes itself by casting rays against the torus and the table,
and meshes read from files.

Object space: y up, the object standing on the table plane y = 0.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numba
import numpy as np

from arsim.core.conventions import normalize, texture_texel_uv
from arsim.core.errors import ArsimError
from arsim.core.resample import to_layout
from arsim.lighting.bases import parse_basis
from arsim.lighting.bases.lightmap import Surface, bake_directional, bake_irradiance_volume, probe_samples
from arsim.lighting.prt import VARIANTS, get_variant, transfer_key
from arsim.render.mesh_lightmap import lightmap_texels, lightmap_unwrap, ray_caster
from arsim.render.meshes import Mesh, grid_mesh, load_mesh, uv_sphere
from arsim.render.renderer import Material, Orbit, SceneObject
from arsim.render.transfer import PrtSettings, with_transfer
from arsim.sensors.table import Table

TABLE_ALBEDO = Table.albedo  # (the dataclass's default: the scenario's unless given)

SPHERE_EXPONENTS = (1.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0, 1280.0)  # thesis figure 5.3


def torus_surface(u: np.ndarray, v: np.ndarray, major: float, minor: float) -> tuple[np.ndarray, ...]:
    """Points, normals and tangents (along increasing u) of a torus around the y axis resting on y = 0:
    u runs around the ring, v around the tube (v = 0 on its outer equator, 0.25 on top)."""
    a, b = 2.0 * np.pi * np.asarray(u), 2.0 * np.pi * np.asarray(v)
    ring = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=-1)
    up = np.array([0.0, 1.0, 0.0])
    normal = ring * np.cos(b)[..., None] + up * np.sin(b)[..., None]
    point = ring * major + normal * minor + up * minor
    tangent = np.stack([np.cos(a), np.zeros_like(a), -np.sin(a)], axis=-1)
    return point, normal, tangent


def torus(major: float = 0.05, minor: float = 0.02, rings: int = 96, segments: int = 48) -> Mesh:
    """The torus mesh; both UV sets are (u, v) (the light map is baked in the same parameterisation)."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, rings + 1), np.linspace(0.0, 1.0, segments + 1), indexing="ij")
    return grid_mesh(*torus_surface(u, v, major, minor), np.stack([u, v], axis=-1))


def torus_distance(p: np.ndarray, major: float, minor: float) -> np.ndarray:
    """Signed distance to the torus resting on y = 0."""
    q = np.stack([np.hypot(p[..., 0], p[..., 2]) - major, p[..., 1] - minor], axis=-1)
    return np.linalg.norm(q, axis=-1) - minor


def scene_distance(p: np.ndarray, major: float, minor: float) -> np.ndarray:
    """Distance to the nearest of the torus and the table top (y = 0)."""
    return np.minimum(torus_distance(p, major, minor), p[..., 1])


def sphere_trace(origins: np.ndarray, directions: np.ndarray, distance, scale: float, reach: float,
                 steps: int = 96, distances: bool = False) -> np.ndarray:
    """Whether each ray (origins and directions broadcast together, (..., 3)) hits the surface of the
    distance function `distance` within `reach`: sphere tracing, each step the distance to the nearest
    surface; scale is the scene's small length (the hit and the step floors are fractions of it). With
    distances, how far along each ray the hit is instead (inf where it hits nothing)."""
    shape = np.broadcast_shapes(origins.shape, directions.shape)
    o = np.broadcast_to(origins, shape).reshape(-1, 3)
    d = np.broadcast_to(directions, shape).reshape(-1, 3)
    hit_at = np.full(len(o), np.inf)
    active = np.arange(len(o))  # the rays still marching (most leave within a few steps: only these step on)
    travelled = np.full(len(o), 1e-3 * scale)
    for _ in range(steps):
        gap = distance(o[active] + d[active] * travelled[:, None])
        touched = gap < 1e-4 * scale
        hit_at[active[touched]] = travelled[touched]
        travelled = travelled + np.maximum(gap, 1e-5 * scale)
        going = ~touched & (travelled <= reach)
        active, travelled = active[going], travelled[going]
        if not len(active):
            break
    return (hit_at if distances else np.isfinite(hit_at)).reshape(shape[:-1])


def torus_texels(major: float, minor: float, size: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """Points, normals and tangents (H, W, 3) of the torus at the centres of an H x W texture's texels,
    row 0 at v = 1 (the light map's and the normal map's parameterisation)."""
    h, w = size
    u, v = texture_texel_uv(h, w)
    return torus_surface(u, v, major, minor)


def tangent_frames(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Any right-handed (t, b) completing unit normals (..., 3) to a frame."""
    helper = np.where(np.abs(normal[..., 1:2]) < 0.9, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    t_axis = normalize(np.cross(helper, normal))
    return t_axis, np.cross(normal, t_axis)


def bake_torus_occlusion(major: float = 0.05, minor: float = 0.02, size: tuple[int, int] = (64, 128),
                         rays: int = 96, seed: int = 0) -> np.ndarray:
    """Ambient-occlusion light map (H, W, 3) of the torus on the table, row 0 at v = 1: per texel, the
    fraction of cosine-weighted rays from the surface that escape the torus and the table top (sphere
    tracing of the exact distance functions). 1 on the top of the ring, near 0 where it touches the table."""
    point, normal, _ = torus_texels(major, minor, size)
    rng = np.random.default_rng(seed)
    # Cosine-weighted directions around each normal (stratified: a side x side grid of the two random numbers).
    side = int(np.sqrt(rays))
    xi = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)
          + rng.random((side * side, 2))) / side
    radius, angle = np.sqrt(xi[:, 0]), 2.0 * np.pi * xi[:, 1]
    local = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.sqrt(1.0 - xi[:, 0])], -1)
    t_axis, b_axis = tangent_frames(normal)
    directions = (local[:, 0, None, None, None] * t_axis + local[:, 1, None, None, None] * b_axis
                  + local[:, 2, None, None, None] * normal)  # (R, H, W, 3)
    origin = point + normal * (1e-3 * minor)
    hits = _torus_scene_hits(origin.reshape(-1, 3), directions.reshape(len(directions), -1, 3), major, minor,
                             6.0 * (major + minor), 96)
    occlusion = (len(directions) - hits.reshape(point.shape[:2])) / len(directions)  # (the share that escapes)
    return np.repeat(occlusion[..., None], 3, axis=-1).astype(np.float32)


@numba.njit(parallel=True, cache=True)
def _torus_scene_hits(origins, directions, major, minor, reach, steps):
    """Per origin (N, 3), how many of its rays (R, N, 3) hit the torus resting on y = 0 or the table top
    within reach: sphere_trace with scene_distance's field, compiled (the numpy march takes 1.4 s for the
    session torus's 64 x 128 texels and 81 rays; this a few hundredths), step for step the same rule."""
    hits = np.zeros(len(origins))
    for i in numba.prange(len(origins)):
        for r in range(directions.shape[0]):
            travelled = 1e-3 * minor
            for _ in range(steps):
                x = origins[i, 0] + directions[r, i, 0] * travelled
                y = origins[i, 1] + directions[r, i, 1] * travelled
                z = origins[i, 2] + directions[r, i, 2] * travelled
                gap = min(np.hypot(np.hypot(x, z) - major, y - minor) - minor, y)
                if gap < 1e-4 * minor:
                    hits[i] += 1
                    break
                travelled += max(gap, 1e-5 * minor)
                if travelled > reach:
                    break
    return hits


def ridges_normal_map(size: tuple[int, int] = (128, 256), ridges: tuple[int, int] = (24, 8),
                      depth: float = 0.6) -> np.ndarray:
    """A tangent-space normal map (H, W, 3) in [0, 1] (eq. 5.1) of a height field of crossed ridges
    h = depth sin(2 pi k u) sin(2 pi m v) / (2 pi k) (slopes up to `depth`), row 0 at v = 1."""
    h, w = size
    u, v = texture_texel_uv(h, w)
    k, m = ridges
    du = depth * np.cos(2 * np.pi * k * u) * np.sin(2 * np.pi * m * v)
    dv = depth * (m / k) * np.sin(2 * np.pi * k * u) * np.cos(2 * np.pi * m * v)
    n = normalize(np.stack([-du, -dv, np.ones_like(du)], axis=-1))
    return (n * 0.5 + 0.5).astype(np.float32)


def _chord_gap(radius: float, steps_per_turn: int) -> float:
    """How far a polygon of steps_per_turn sides inscribed in a circle of this radius departs from it."""
    return radius * (1.0 - np.cos(np.pi / steps_per_turn))


def torus_proxy(major: float, minor: float, rings: int = 16, segments: int = 8) -> Mesh | None:
    """A coarse closed mesh (rings x segments cells) that holds the torus, for the renderer to ray-cast it
    through (README: AR session, Rendering speed): its tube a polygon about the tube's circle, widened by
    the sag of the ring's chords (where a face spans two of the polygons it falls that far towards the
    axis). None where that tube would reach the axis (a torus nearly a horn: the mesh would pass through
    itself)."""
    sag = (major + 2.0 * minor) * (1.0 - np.cos(np.pi / rings)) / np.cos(np.pi / rings)
    tube = (minor + sag) / np.cos(np.pi / segments)
    if tube >= major:
        return None
    u, v = np.meshgrid(np.linspace(0.0, 1.0, rings + 1), np.linspace(0.0, 1.0, segments + 1), indexing="ij")
    point, normal, tangent = torus_surface(u, v, major, minor)
    return grid_mesh(point + normal * (tube - minor), normal, tangent, np.stack([u, v], axis=-1))


def torus_lods(major: float, minor: float, rings: int) -> tuple[tuple[Mesh, float], ...]:
    """Coarser tori than rings x rings / 2, down to 16 x 8, with their departures from the torus (the ring's
    and the tube's chord gaps added). The steps are close (departures 1.2-1.5 times apart): the renderer
    draws the coarsest within its half-pixel limit, and a finer mesh than that costs llvmpipe its pixels
    shaded again (steps twice apart drew 7 % more of the objects pass along the default AR path)."""
    steps = [r for r in (80, 72, 64, 56, 48, 40, 32, 28, 24, 20, 16) if r < rings]
    return tuple((torus(major, minor, r, r // 2), _chord_gap(major + minor, r) + _chord_gap(minor, r // 2)) for r in steps)


def translation(x: float, y: float, z: float) -> np.ndarray:
    model = np.eye(4)
    model[:3, 3] = [x, y, z]
    return model


@dataclass(frozen=True)
class ObjectLighting:
    """An object's lighting, parsed once from its [[render.objects]] lighting string."""

    kind: str  # "ibl", "lightmap-ao", "volume", "inm" (a directional light map) or "prt"
    basis: str = ""  # inm: the basis and its count, e.g. "modh6"
    variant: str = ""  # prt: the variant (lighting.prt.VARIANTS)
    per_texel: bool = False  # prt: the transfer per light-map texel (else per vertex)

    @property
    def inm(self) -> bool:
        return self.kind == "inm"

    @property
    def texels(self) -> bool:
        """Whether the object needs light-map texels (a directional light map, or PRT per texel)."""
        return self.kind == "inm" or self.per_texel


IBL = ObjectLighting("ibl")


def parse_lighting(o) -> ObjectLighting:
    """An object's lighting ([[render.objects]] lighting): "ibl", "lightmap-ao", "volume" or
    "inm-<basis><count>" (checked: an unknown basis, a count it does not have, or more inm_terms, raises
    ArsimError)."""
    if o.lighting in ("ibl", "lightmap-ao", "volume"):
        return IBL if o.lighting == "lightmap-ao" and not o.light_map else ObjectLighting(o.lighting)
    if not o.lighting.startswith(("inm-", "prt-")):
        raise ArsimError(f"[[render.objects]] lighting = \"{o.lighting}\": use ibl, lightmap-ao, volume, inm-BASIS "
                         f"(e.g. inm-modh6, inm-h4, inm-sh9) or prt-VARIANT ({', '.join('prt-' + v for v in VARIANTS)})")
    if o.orbit_m > 0:
        raise ArsimError(f"[[render.objects]] lighting = \"{o.lighting}\" with orbit_m = {o.orbit_m:g}: a directional light map "
                         f"holds the light where the object stands (so does a PRT transfer); give an object that moves lighting = volume (or ibl)")
    if o.lighting.startswith("prt-"):
        get_variant(o.lighting[4:])  # (an unknown one refused here)
        return ObjectLighting("prt", variant=o.lighting[4:], per_texel=o.prt_at == "texel")
    basis, count = parse_basis(o.lighting[4:])
    if o.inm_terms > count:
        raise ArsimError(f"[[render.objects]] inm_terms = {o.inm_terms}: {o.lighting} has {count} terms; give 1 to {count} (0: all)")
    return ObjectLighting("inm", f"{basis.name}{count}")


def disc(radius: float, rings: int = 16, segments: int = 96) -> Mesh:
    """A flat disc on the table (y slightly above 0), normal +y, tangent +x; both UV sets planar: u along
    +x, v along -z (the bitangent n x t), the disc inscribed in the unit square."""
    r, phi = np.meshgrid(np.linspace(0.0, radius, rings + 1), np.linspace(0.0, 2 * np.pi, segments + 1), indexing="ij")
    x, z = r * np.cos(phi), -r * np.sin(phi)
    points = np.stack([x, np.full_like(x, 1e-4 * radius), z], axis=-1)
    normals = np.broadcast_to([0.0, 1.0, 0.0], points.shape)
    tangents = np.broadcast_to([1.0, 0.0, 0.0], points.shape)
    uvs = np.stack([0.5 + 0.5 * x / radius, 0.5 - 0.5 * z / radius], axis=-1)
    return grid_mesh(points, normals, tangents, uvs)


def disc_texels(radius: float, size: int, offset: np.ndarray) -> Surface:
    """The disc's light-map texels (size x size over its square, row 0 at v = 1, i.e. z = -radius); texels
    whose centre lies within a texel of the rim count, so that bilinear lookups at the rim have values."""
    u, v = texture_texel_uv(size, size)
    x, z = (2 * u - 1) * radius, -(2 * v - 1) * radius
    points = np.stack([x, np.zeros_like(x), z], axis=-1) + offset
    normals = np.broadcast_to([0.0, 1.0, 0.0], points.shape).copy()
    tangents = np.broadcast_to([1.0, 0.0, 0.0], points.shape).copy()
    valid = np.hypot(x, z) <= radius * (1 + 2.0 / size)
    return Surface(points, normals, tangents, valid)


def _torus_object(o, x: float, z: float, lighting: ObjectLighting) -> SceneObject:
    minor = 0.4 * o.size_m
    offset = np.array([x, 0.0, z])
    size = (o.lightmap_size, 2 * o.lightmap_size)

    def texels() -> Surface:
        points, normals, tangents = torus_texels(o.size_m, minor, size)
        return Surface(points + offset, normals, tangents, np.ones(size, bool))

    material = Material(o.kd, o.ks, o.exponent, bake_torus_occlusion(o.size_m, minor) if lighting.kind == "lightmap-ao" else None,
                        ridges_normal_map() if o.normal_map else None, o.method, basis=lighting.basis,
                        inm_terms=o.inm_terms or None)
    proxy = torus_proxy(o.size_m, minor)
    return SceneObject(torus(o.size_m, minor), material, translation(x, 0.0, z), torus_lods(o.size_m, minor, 96),
                       lightmap_surface=texels, distance=lambda p: torus_distance(p - offset, o.size_m, minor),
                       torus=(o.size_m, minor, proxy) if proxy is not None else None)


def _disc_object(o, x: float, z: float, lighting: ObjectLighting) -> SceneObject:
    offset = np.array([x, 0.0, z])  # (lightmap-ao: plain IBL, the thesis bakes occlusion for the torus only)
    material = Material(o.kd, o.ks, o.exponent, method=o.method, basis=lighting.basis, inm_terms=o.inm_terms or None)
    return SceneObject(disc(o.size_m), material, translation(x, 0.0, z),
                       lightmap_surface=lambda: disc_texels(o.size_m, o.lightmap_size, offset))


def scene_objects(section, table_albedo: tuple[float, float, float] = TABLE_ALBEDO) -> list[SceneObject]:
    """The scenario's virtual objects ([[render.objects]], a RenderObjectSection each) as SceneObjects; a
    mesh that cannot be read, or a lighting that cannot be, raises ArsimError. Directional light maps
    (lighting = inm-...) are baked later, from the light: light_objects. table_albedo: the scenario's [ar]
    table_albedo (the light the table sends on, for PRT's interreflection)."""
    objects = []
    for o in section.objects:
        x, z = o.position_m
        lighting = parse_lighting(o)
        added = len(objects)
        if o.kind in ("sphere_row", "sphere"):
            row = o.kind == "sphere_row"
            spacing = 2.6 * o.size_m
            for k, exponent in enumerate(SPHERE_EXPONENTS if row else (o.exponent,)):
                dx = (k - (len(SPHERE_EXPONENTS) - 1) / 2) * spacing if row else 0.0
                objects.append(_sphere_object(o, np.array([x + dx, o.size_m, z]), exponent, lighting, (32, 64) if row else (48, 96)))
        elif o.kind == "mesh":
            objects.append(mesh_object(o, lighting))
        elif o.kind == "disc":
            objects.append(_disc_object(o, x, z, lighting))
        else:
            objects.append(_torus_object(o, x, z, lighting))
        for k in range(added, len(objects)):
            if o.material == "ggx":
                # (a row: roughness 0 to 1 along it, as the Phong row's exponents; exponent 1: only the irradiance map is read)
                roughness = k - added if o.kind == "sphere_row" else None
                roughness = o.roughness if roughness is None else roughness / (len(SPHERE_EXPONENTS) - 1)
                material = dataclasses.replace(objects[k].material, model="ggx", base_color=tuple(o.base_color),
                                               metallic=o.metallic, roughness=float(roughness), exponent=1.0)
                objects[k] = dataclasses.replace(objects[k], material=material)
            if lighting.kind == "volume":
                material = dataclasses.replace(objects[k].material, volume_lit=True, light_map=None)
                objects[k] = dataclasses.replace(objects[k], material=material)
            if o.orbit_m > 0:
                objects[k] = dataclasses.replace(objects[k], orbit=Orbit(o.orbit_m, o.orbit_period_s))
            if lighting.kind == "prt":  # (the transfer is computed by light_objects, with the scene's visibility)
                material = dataclasses.replace(objects[k].material, prt_variant=lighting.variant, light_map=None)
                settings = PrtSettings(lighting.variant, o.prt_order, lighting.per_texel, o.prt_samples, o.prt_clusters,
                                       o.prt_bounces, float(np.mean(o.kd)), float(np.mean(table_albedo)))
                objects[k] = dataclasses.replace(objects[k], material=material, transfer=settings)
    return objects


def _sphere_distance(centre: np.ndarray, radius: float):
    return lambda p: np.linalg.norm(p - centre, axis=-1) - radius


def sphere_texels(radius: float, size: tuple[int, int], centre: np.ndarray) -> Surface:
    """The light-map texels (H x W, row 0 at v = 1) of a sphere in uv_sphere's parameterisation (u the
    longitude / 2 pi, v = 1 - polar angle / pi), on the exact sphere, with uv_sphere's tangents."""
    h, w = size
    u, v = texture_texel_uv(h, w)
    theta, phi = np.pi * (1.0 - v), 2.0 * np.pi * u
    normals = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], axis=-1)
    tangents = np.stack([np.cos(phi), np.zeros_like(phi), -np.sin(phi)], axis=-1)
    return Surface(centre + radius * normals, normals, tangents, np.ones(size, bool))


def _sphere_object(o, centre: np.ndarray, exponent: float, lighting: ObjectLighting,
                   tessellation: tuple[int, int]) -> SceneObject:
    """A sphere of the scenario's (a row's: one of them) standing on the table at centre; with lighting =
    inm-..., drawn as its mesh (the light map in its UVs), else ray-cast (lightmap-ao: plain IBL, the thesis
    bakes occlusion for the torus only)."""
    material = Material(o.kd, o.ks, exponent, method=o.method, basis=lighting.basis, inm_terms=o.inm_terms or None)
    size = (o.lightmap_size, 2 * o.lightmap_size)
    return SceneObject(uv_sphere(o.size_m, *tessellation), material, translation(*centre), sphere=o.size_m,
                       distance=_sphere_distance(centre, o.size_m),
                       lightmap_surface=(lambda: sphere_texels(o.size_m, size, centre)) if lighting.texels else None)


LIGHT_SIZE = 32  # the light's angle map the directional light maps sum (every texel's energy kept)


VOLUME_GRID = (9, 5, 9)  # grid points of the irradiance volume over the objects' box (x, y, z)


@dataclass(frozen=True)
class Occlusion:
    """The scene's rays: blocked(origins (T, 3), directions (K, T, 3)) -> (K, T) whether each hits the
    table top or an object that stands still and is not lit by the volume (by its distance function or its
    mesh); distance(...) the same as how far (inf: nothing); the occluders; a key of that geometry (their
    meshes where they stand) for caches."""

    blocked: object
    distance: object
    occluders: list
    key: str


def scene_occlusion(objects: list[SceneObject], lit_by_volume: list[bool]) -> Occlusion:
    """The rays of the scene that the objects standing still make with the table (see Occlusion)."""
    occluders = [o for o, moving in zip(objects, lit_by_volume) if not moving and o.orbit is None]
    shapes = [o.distance for o in occluders if o.distance is not None]
    scale = 0.01  # metres: the hit and step floors of the sphere tracing

    def field(p):
        return np.minimum.reduce([p[..., 1]] + [d(p) for d in shapes])

    meshes = [(o.mesh, o.model) for o in occluders if o.mesh_occludes]
    cast = ray_caster(meshes) if meshes else None
    cast_far = ray_caster(meshes, distances=True) if meshes else None

    def blocked(origins, directions):
        origins = origins + directions * 2e-5
        hit = sphere_trace(origins, directions, field, scale, 2.0)
        return hit | cast(origins, directions) if cast is not None else hit

    def distance(origins, directions):
        far = sphere_trace(origins + directions * 2e-5, directions, field, scale, 2.0, distances=True)
        return np.minimum(far, cast_far(origins + directions * 2e-5, directions)) + 2e-5 if cast_far is not None else far + 2e-5

    key = transfer_key("table y=0", *[a for o in occluders for a in (o.mesh.positions, o.mesh.indices, o.model,
                                                                        o.distance is not None, o.mesh_occludes)])
    return Occlusion(blocked, distance, occluders, key)


GGX_CUBE_SIZE = 128  # faces of the GGX prefiltered cube map's level 0 (the mirror): 6 levels, 128 to 4 texels
_GGX_CHAINS: dict[str, list[np.ndarray]] = {}  # the chains computed this process, by the light's content


def ggx_chain(light: np.ndarray, size: int = GGX_CUBE_SIZE) -> list[np.ndarray]:
    """The GGX prefiltered cube map (levels (6, size >> p, size >> p, 3), lighting.ggx.prefilter_ggx) of an
    angle-map light (world frame): computed once per light (a second call with the same content returns the
    same list, so that a renderer uploads it once)."""
    import hashlib

    from arsim.core.resample import to_cube
    from arsim.lighting.ggx import prefilter_ggx

    data = np.ascontiguousarray(light, dtype=np.float32)
    key = hashlib.sha1(data.tobytes() + repr((data.shape, size)).encode()).hexdigest()
    if key not in _GGX_CHAINS:
        if len(_GGX_CHAINS) >= 8:  # (a session holds a few lights: the probe, the truth, the estimates)
            _GGX_CHAINS.pop(next(iter(_GGX_CHAINS)))
        _GGX_CHAINS[key] = prefilter_ggx(to_cube(data, size).astype(np.float64))
    return _GGX_CHAINS[key]


def light_objects(objects: list[SceneObject], light: np.ndarray) -> list[SceneObject]:
    """The objects with their directional light maps (lighting = inm-...), their PRT transfer (lighting =
    prt-..., relit from this light) and the scene's irradiance volume (lighting = volume) baked from an
    angle-map light (world frame): visibility against the table top and every object that stands still and
    is not lit by the volume (those move, or may), by its distance function or its mesh; the volume's box
    holds every object wherever it goes. GGX materials (material = ggx) get the light's prefiltered cube map
    (ggx_chain)."""
    if any(o.material.model == "ggx" for o in objects):
        if light is None:
            raise ArsimError('material = "ggx" objects are lit by the probe\'s GGX prefiltered cube map, computed from the '
                             'probe: give the probe (--env PROBE.exr, or let the capture make it) rather than maps baked before')
        chain = ggx_chain(light)
        objects = [dataclasses.replace(o, material=dataclasses.replace(o.material, ggx_chain=chain))
                   if o.material.model == "ggx" else o for o in objects]
    inm = [o.material.basis and o.lightmap_surface is not None for o in objects]
    lit_by_volume = [o.material.volume_lit for o in objects]
    if not any(inm) and not any(lit_by_volume) and all(o.transfer is None for o in objects):
        return objects
    occlusion = scene_occlusion(objects, lit_by_volume)
    blocked = occlusion.blocked
    directions, weighted = probe_samples(to_layout(light, "anglemap", LIGHT_SIZE))
    volume = None
    if any(lit_by_volume):
        corners = np.concatenate([o.swept_corners() for o in objects])
        low, high = corners.min(axis=0) - 0.02, corners.max(axis=0) + 0.02
        low[1] = max(low[1], 1e-3)  # (grid points on the table would see nothing of the lower half)
        axes = [np.linspace(low[i], high[i], VOLUME_GRID[i]) for i in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        volume = (bake_irradiance_volume(grid, directions, weighted, blocked), low, high)
    out = []
    for o, baked, moving in zip(objects, inm, lit_by_volume):
        if baked:
            basis, count = parse_basis(o.material.basis)
            coefficients = bake_directional(o.lightmap_surface(), basis, count, directions, weighted, blocked)
            o = dataclasses.replace(o, material=dataclasses.replace(o.material, directional_map=coefficients))
        elif moving:
            o = dataclasses.replace(o, material=dataclasses.replace(o.material, irradiance_volume=volume))
        elif o.transfer is not None:
            o = with_transfer(o, o.transfer, occlusion, light)
        out.append(o)
    return out


def mesh_object(o, lighting: ObjectLighting = IBL) -> SceneObject:
    """A mesh file's object: scaled so that its bounding box's largest side is size_m, standing on the
    table (its lowest point at y = 0) with its box centred over position_m; the ridges normal map where
    it has texture coordinates. With lighting = inm-..., a second UV set unwrapped for its directional
    light map (lightmap_size x lightmap_size at most)."""
    if o.mesh is None:
        raise ArsimError("[[render.objects]] kind = \"mesh\" needs mesh = \"FILE\" (an OBJ, PLY, STL, OFF or glTF file)")
    mesh, textured = load_mesh(o.mesh)
    low, high = mesh.positions.min(axis=0).astype(np.float64), mesh.positions.max(axis=0).astype(np.float64)
    extent = float((high - low).max())
    if extent <= 0.0:
        raise ArsimError(f"{o.mesh}: the mesh has no extent (all its vertices coincide); fix the file")
    scale = o.size_m / extent
    centre = (low + high) / 2
    model = translation(o.position_m[0] - scale * centre[0], -scale * low[1], o.position_m[1] - scale * centre[2])
    model[:3, :3] *= scale
    material = Material(o.kd, o.ks, o.exponent, None, ridges_normal_map() if o.normal_map and textured else None, o.method)
    surface = None
    if lighting.texels:
        mesh, shape = lightmap_unwrap(mesh, o.lightmap_size)
        material = dataclasses.replace(material, basis=lighting.basis, inm_terms=o.inm_terms or None)
        surface = (lambda: lightmap_texels(mesh, model, shape))
    return SceneObject(mesh, material, model, lightmap_surface=surface, mesh_occludes=True)
