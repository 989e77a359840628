"""A glTF 2.0 scene lit by an image-based light (EXT_lights_image_based, pygltflib): the light's specular images
(RGBD PNGs, one per GGX level and cube face) and irradiance SH, and three spheres to look at it with: a white
diffuse one, a rough metal one and a mirror (README: Maps for engines)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import pygltflib as g

from arsim import __version__
from arsim.core.conventions import CUBE_FACE_SUFFIXES
from arsim.core.errors import ArsimError
from arsim.core.files import atomic_path, write_bytes_atomic, write_text_atomic

EXTENSION = "EXT_lights_image_based"
SPHERE_RADIUS_M = 0.1
SPHERES = (  # name, base colour, metallic, roughness, x of the centre
    ("diffuse", (0.8, 0.8, 0.8, 1.0), 0.0, 1.0, -0.25),
    ("rough metal", (0.95, 0.93, 0.88, 1.0), 1.0, 0.5, 0.0),
    ("mirror", (1.0, 1.0, 1.0, 1.0), 1.0, 0.0, 0.25),
)


def rgbd(rgb: np.ndarray) -> np.ndarray:
    """(..., 4) uint8: radiance packed as RGBD the way Babylon.js packs it (EXT_lights_image_based's PNGs):
    D = floor(max(255 / max(r, g, b), 1)) / 255, colour (rgb D)^(1/2.2); decoded as (colour^2.2) / D. Up to 255."""
    rgb = np.maximum(np.asarray(rgb, dtype=np.float64), 0.0)
    peak = np.maximum(rgb.max(axis=-1, keepdims=True), 1e-7)
    d = np.clip(np.floor(np.maximum(255.0 / peak, 1.0)), 1.0, 255.0) / 255.0
    colour = np.clip(rgb * d, 0.0, 1.0) ** (1 / 2.2)
    return np.round(np.concatenate([colour, d], axis=-1) * 255.0).astype(np.uint8)


def write_png_rgba8(path: Path, rgba: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(rgba[..., [2, 1, 0, 3]])):
            raise ArsimError(f"{path}: could not be written as PNG")


def uv_sphere(rings: int = 32, segments: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit sphere: positions (V, 3) float32 (= its normals), triangle indices (T * 3,) uint16, counter-clockwise
    seen from outside (glTF's front faces)."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    positions = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    r, s = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = r * (segments + 1) + s
    b = a + segments + 1
    triangles = np.concatenate([np.stack([a, b, a + 1], -1).reshape(-1, 3), np.stack([a + 1, b, b + 1], -1).reshape(-1, 3)])
    return positions.astype(np.float32), positions.astype(np.float32), triangles.reshape(-1).astype(np.uint16)


def write_ibl_scene(folder: Path, chain: Sequence[np.ndarray], irradiance_sh: np.ndarray) -> list[Path]:
    """folder/ibl.gltf, ibl.bin and specular_<level>_<face>.png: the light (GGX chain (6, N >> p, N >> p, 3) per
    level p, the irradiance's SH E_lm (9, 3)) and the spheres. Returns the files."""
    folder.mkdir(parents=True, exist_ok=True)
    files, images, specular = [], [], []
    for level, faces in enumerate(chain):
        names = []
        for face, tag in zip(faces, CUBE_FACE_SUFFIXES):
            name = f"specular_{level}_{tag}.png"
            write_png_rgba8(folder / name, rgbd(face))
            files.append(folder / name)
            names.append(len(images))
            images.append(g.Image(uri=name, mimeType="image/png"))
        specular.append(names)

    positions, normals, indices = uv_sphere()
    blob = positions.tobytes() + normals.tobytes() + indices.tobytes()
    n_pos = positions.nbytes
    gltf = g.GLTF2(
        asset=g.Asset(version="2.0", generator=f"arsim {__version__}"),
        scene=0,
        scenes=[g.Scene(nodes=[0, 1, 2], extensions={EXTENSION: {"light": 0}})],
        nodes=[g.Node(name=name, mesh=k, translation=[x, SPHERE_RADIUS_M, 0.0], scale=[SPHERE_RADIUS_M] * 3)
               for k, (name, _, _, _, x) in enumerate(SPHERES)],
        meshes=[g.Mesh(name=name, primitives=[g.Primitive(attributes=g.Attributes(POSITION=0, NORMAL=1), indices=2, material=k)])
                for k, (name, *_) in enumerate(SPHERES)],
        materials=[g.Material(name=name, pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=list(colour), metallicFactor=metallic, roughnessFactor=roughness))
            for name, colour, metallic, roughness, _ in SPHERES],
        accessors=[
            g.Accessor(bufferView=0, componentType=g.FLOAT, count=len(positions), type=g.VEC3,
                       min=positions.min(axis=0).tolist(), max=positions.max(axis=0).tolist()),
            g.Accessor(bufferView=1, componentType=g.FLOAT, count=len(normals), type=g.VEC3),
            g.Accessor(bufferView=2, componentType=g.UNSIGNED_SHORT, count=len(indices), type=g.SCALAR),
        ],
        bufferViews=[
            g.BufferView(buffer=0, byteOffset=0, byteLength=n_pos, target=g.ARRAY_BUFFER),
            g.BufferView(buffer=0, byteOffset=n_pos, byteLength=normals.nbytes, target=g.ARRAY_BUFFER),
            g.BufferView(buffer=0, byteOffset=2 * n_pos, byteLength=indices.nbytes, target=g.ELEMENT_ARRAY_BUFFER),
        ],
        buffers=[g.Buffer(uri="ibl.bin", byteLength=len(blob))],
        images=images,
        extensionsUsed=[EXTENSION],
        extensions={EXTENSION: {"lights": [{
            "name": "arsim",
            "rotation": [0.0, 0.0, 0.0, 1.0],
            "intensity": 1.0,
            "irradianceCoefficients": np.asarray(irradiance_sh, dtype=np.float64).tolist(),
            "specularImageSize": int(chain[0].shape[1]),
            "specularImages": specular,
        }]}},
    )
    write_bytes_atomic(folder / "ibl.bin", blob)
    write_text_atomic(folder / "ibl.gltf", gltf.to_json(indent=1) + "\n")
    return files + [folder / "ibl.bin", folder / "ibl.gltf"]
