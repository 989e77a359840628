"""arsim export: maps for engines. KTX2 files read back by a parse of the container written here from the KTX 2.0
specification (not arsim's writer), the GGX chain and the BRDF table against references, Filament's sh.txt
against arsim's irradiance maps, the glTF scene through pygltflib, and bad inputs through the command line."""

import json
import re
import struct
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pygltflib
import pytest
from numpy.polynomial.legendre import leggauss

from arsim.core.conventions import (CUBE_FACES, anglemap_directions, anglemap_disk_mask, cube_directions,
                                    cube_solid_angles)
from arsim.core.hdr_io import read_hdr, write_exr
from arsim.core.resample import to_cube, to_layout
from arsim.lighting.accurate import accurate_maps
from arsim.lighting.bake_output import write_bake
from arsim.lighting.export import export_maps, load_source
from arsim.lighting.ggx import brdf_lut, cube_mip_chain, level_roughness, prefilter_level
from arsim.lighting.methods import BakeResult, MapParameters
from arsim.lighting.sh import sh_maps
from tests.conftest import ASSETS

KTX2_IDENTIFIER = bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A])


def parse_ktx2(data: bytes) -> dict:
    """Every field of an uncompressed KTX2 file (KTX File Format Specification 2.0, section 3), checked against
    the file's own size as it is read; the levels decoded as half floats (faces, height, width, channels)."""
    assert data[:12] == KTX2_IDENTIFIER
    names = ("vkFormat", "typeSize", "pixelWidth", "pixelHeight", "pixelDepth", "layerCount", "faceCount", "levelCount",
             "supercompressionScheme")
    f = dict(zip(names, struct.unpack_from("<9I", data, 12)))
    f["dfdByteOffset"], f["dfdByteLength"], f["kvdByteOffset"], f["kvdByteLength"] = struct.unpack_from("<4I", data, 48)
    f["sgdByteOffset"], f["sgdByteLength"] = struct.unpack_from("<2Q", data, 64)
    count = max(1, f["levelCount"])
    f["levels"] = [struct.unpack_from("<3Q", data, 80 + 24 * p) for p in range(count)]
    assert f["dfdByteOffset"] == 80 + 24 * count
    # Data format descriptor: total size, then one basic block (Khronos Data Format Specification 1.3, 5.1)
    dfd = data[f["dfdByteOffset"]:f["dfdByteOffset"] + f["dfdByteLength"]]
    total, = struct.unpack_from("<I", dfd, 0)
    first, version, block_size = struct.unpack_from("<IHH", dfd, 4)
    model, primaries, transfer, flags = dfd[12:16]
    samples = []
    for k in range((block_size - 24) // 16):
        offset, length, channel, *_ = struct.unpack_from("<HBB4BII", dfd, 28 + 16 * k)
        lower, upper = struct.unpack_from("<II", dfd, 28 + 16 * k + 8)
        samples.append({"bitOffset": offset, "bitLength": length + 1, "channel": channel & 0x0F,
                        "qualifiers": channel & 0xF0, "lower": lower, "upper": upper})
    f["dfd"] = {"totalSize": total, "descriptorType": first >> 17, "vendorId": first & 0x1FFFF, "version": version,
                "blockSize": block_size, "colorModel": model, "colorPrimaries": primaries, "transferFunction": transfer,
                "flags": flags, "texelBlockDimension": list(dfd[16:20]), "bytesPlane": list(dfd[20:28]), "samples": samples}
    # Key/value data: length, key NUL value, padding to 4
    kv, at, end = {}, f["kvdByteOffset"], f["kvdByteOffset"] + f["kvdByteLength"]
    while at < end:
        length, = struct.unpack_from("<I", data, at)
        entry = data[at + 4:at + 4 + length]
        key, _, value = entry.partition(b"\x00")
        kv[key.decode()] = value
        at += 4 + length + (-length % 4)
    assert at == end
    f["keys_in_order"] = list(kv)
    f["kv"] = kv
    return f


def ktx2_levels(f: dict, data: bytes, channels: int) -> list[np.ndarray]:
    faces, width = f["faceCount"], f["pixelWidth"]
    height = f["pixelHeight"]
    return [np.frombuffer(data, "<f2", count=length // 2, offset=offset).astype(np.float64)
            .reshape(faces, max(1, height >> p), max(1, width >> p), channels)
            for p, (offset, length, _) in enumerate(f["levels"])]


def spot_probe(direction, n: int = 64, path: Path | None = None) -> np.ndarray:
    """An angle map: 1 everywhere, 500 within 12 degrees of `direction`."""
    d = anglemap_directions(n)
    probe = np.ones((n, n, 3), dtype=np.float32)
    probe[(d @ np.asarray(direction, dtype=float)) > np.cos(np.radians(12))] = 500.0
    probe[~anglemap_disk_mask(n)] = 0.0
    if path is not None:
        write_exr(path, probe)
    return probe


@pytest.fixture(scope="module")
def probe_export(tmp_path_factory):
    """A probe with a bright spot at +x exported as KTX2, Filament's files and glTF at 32 x 32 faces."""
    folder = tmp_path_factory.mktemp("export")
    path = folder / "probe.exr"
    spot_probe([1.0, 0.0, 0.0], 128, path)
    out = folder / "out"
    out.mkdir()
    result = export_maps(load_source(path), ["ktx2", "filament", "gltf"], out, size=32)
    return path, out, result


def test_ktx2_container_read_back_field_by_field(probe_export):
    _, out, _ = probe_export
    data = (out / "specular_ggx.ktx2").read_bytes()
    f = parse_ktx2(data)
    assert f["vkFormat"] == 97 and f["typeSize"] == 2  # VK_FORMAT_R16G16B16A16_SFLOAT, 16-bit components
    assert (f["pixelWidth"], f["pixelHeight"], f["pixelDepth"], f["layerCount"], f["faceCount"]) == (32, 32, 0, 0, 6)
    assert f["levelCount"] == 4 and f["supercompressionScheme"] == 0  # 32, 16, 8, 4
    assert f["sgdByteOffset"] == 0 and f["sgdByteLength"] == 0
    dfd = f["dfd"]
    assert dfd["totalSize"] == f["dfdByteLength"] == f["kvdByteOffset"] - f["dfdByteOffset"] == 4 + 24 + 4 * 16
    assert (dfd["descriptorType"], dfd["vendorId"], dfd["version"], dfd["blockSize"]) == (0, 0, 2, 24 + 4 * 16)
    assert (dfd["colorModel"], dfd["colorPrimaries"], dfd["transferFunction"], dfd["flags"]) == (1, 1, 1, 0)  # RGBSDA, BT709, linear
    assert dfd["texelBlockDimension"] == [0, 0, 0, 0] and dfd["bytesPlane"] == [8, 0, 0, 0, 0, 0, 0, 0]
    assert [(s["channel"], s["bitOffset"], s["bitLength"], s["qualifiers"]) for s in dfd["samples"]] == \
        [(0, 0, 16, 0xC0), (1, 16, 16, 0xC0), (2, 32, 16, 0xC0), (15, 48, 16, 0xC0)]  # R, G, B, A; float, signed
    assert all(s["lower"] == 0xBF800000 and s["upper"] == 0x3F800000 for s in dfd["samples"])
    assert f["keys_in_order"] == sorted(f["keys_in_order"]) and f["kv"]["KTXorientation"] == b"rd\x00"
    assert f["kv"]["KTXwriter"].startswith(b"arsim ") and f["kv"]["arsim.roughness"] == b"0 0.333333 0.666667 1\x00"
    # levels: smallest first, each on an 8-byte boundary (lcm(8, 4)), the right length, level 0 ending the file
    offsets = [(offset, length) for offset, length, _ in f["levels"]]
    for p, (offset, length) in enumerate(offsets):
        assert offset % 8 == 0 and length == 6 * (32 >> p) ** 2 * 8 and f["levels"][p][2] == length
    assert all(offsets[p + 1][0] + offsets[p + 1][1] <= offsets[p][0] for p in range(len(offsets) - 1))
    assert offsets[-1][0] >= f["kvdByteOffset"] + f["kvdByteLength"] and offsets[0][0] + offsets[0][1] == len(data)


@pytest.mark.parametrize("direction, face", [([1, 0, 0], 0), ([0, -1, 0], 3), ([0, 0, -1], 5)])
def test_a_bright_spot_lands_on_its_face(tmp_path, direction, face):
    """The skybox's face order is +X, -X, +Y, -Y, +Z, -Z and the spot sits at the face's centre."""
    spot_probe(direction, 64, tmp_path / "p.exr")
    out = tmp_path / "out"
    out.mkdir()
    export_maps(load_source(tmp_path / "p.exr"), ["ktx2"], out, size=16)
    data = (out / "skybox.ktx2").read_bytes()
    cube = ktx2_levels(parse_ktx2(data), data, 4)[0]
    brightest = np.unravel_index(np.argmax(cube[..., 0]), cube.shape[:3])
    assert brightest[0] == face and max(abs(brightest[1] - 7.5), abs(brightest[2] - 7.5)) <= 1


def test_ggx_level_0_is_the_input_cube_and_alpha_is_one(probe_export):
    path, out, _ = probe_export
    data = (out / "specular_ggx.ktx2").read_bytes()
    levels = ktx2_levels(parse_ktx2(data), data, 4)
    expected = to_cube(to_layout(read_hdr(path), "anglemap"), 32)
    assert np.all(np.abs(levels[0][..., :3] - expected) <= np.abs(expected) * 2.0**-11 + 1e-7)  # half float's rounding
    assert all(np.all(level[..., 3] == 1.0) for level in levels)
    # the spot spreads with roughness, keeping the mean radiance on the +X face's centre the brightest
    assert all(np.unravel_index(np.argmax(level[..., 0]), level.shape[:3])[0] == 0 for level in levels)
    assert levels[1][0, ..., 0].max() < levels[0][0, ..., 0].max()


def test_ggx_level_against_an_exact_convolution():
    """A level of the chain against the sum over every source texel of the same lobe (n = v = r, the radiance
    weighted by D(h) (n.l) / 4, i.e. n.l over the sampling density), on a smooth light where the filtered
    lookups' blur is of no account: within 1 %."""
    size = 32
    d = cube_directions(size)
    cube = (1.0 + 0.8 * d[..., 0:1] + 0.5 * d[..., 1:2] ** 2 + 0.3 * d[..., 2:3] * d[..., 0:1]) * np.array([1.0, 0.7, 0.4])
    roughness = 0.6
    level = prefilter_level(cube_mip_chain(cube), 8, roughness, samples=256)
    alpha2 = roughness**4
    src_d, src_l = d.reshape(-1, 3), cube.reshape(-1, 3)
    omega = np.broadcast_to(cube_solid_angles(size), (6, size, size)).reshape(-1)
    for face, row, col in [(0, 3, 4), (2, 0, 0), (5, 6, 2)]:
        n = cube_directions(8)[face, row, col]
        nl = src_d @ n
        h = src_d + n
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        nh = h @ n
        w = np.where(nl > 0, alpha2 / (np.pi * (nh**2 * (alpha2 - 1) + 1) ** 2) * nl * omega, 0.0)
        exact = (src_l * w[:, None]).sum(axis=0) / w.sum()
        assert np.allclose(level[face, row, col], exact, rtol=0.01), (level[face, row, col], exact)


def split_sum_quadrature(n_dot_v: float, roughness: float) -> np.ndarray:
    """(scale, bias) of the split sum (Karis 2013, "Real Shading in Unreal Engine 4", the environment BRDF) by
    Gauss-Legendre quadrature over the light's direction on the hemisphere, 400 x 160 nodes (1500 x 600 agree to 1e-13): the GGX
    distribution, the height-correlated Smith visibility (Heitz 2014, eq. 99), Schlick's Fc = (1 - v.h)^5. The
    reference the table is held to, computed here without importance sampling."""
    a2 = roughness**4
    x, wx = leggauss(400)
    y, wy = leggauss(160)
    theta, phi = (x + 1) * np.pi / 4, (y + 1) * np.pi / 2  # phi over [0, pi], doubled: v lies in the xz plane
    t, p = np.meshgrid(theta, phi, indexing="ij")
    weight = np.outer(wx * np.pi / 4, wy * np.pi) * np.sin(t)
    light = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    v = np.array([np.sqrt(1 - n_dot_v**2), 0.0, n_dot_v])
    h = light + v
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    nh, vh, nl = h[..., 2], h @ v, light[..., 2]
    d = a2 / (np.pi * (nh * nh * (a2 - 1) + 1) ** 2)
    vis = 0.5 / (nl * np.sqrt(n_dot_v**2 * (1 - a2) + a2) + n_dot_v * np.sqrt(nl * nl * (1 - a2) + a2))
    fc = (1 - vh) ** 5
    g = d * vis * nl * weight
    return np.array([((1 - fc) * g).sum(), (fc * g).sum()])


def test_brdf_table_against_a_quadrature_reference(probe_export):
    """Three texels of the written table (the 16-bit PNG and the KTX2) within 1 % of the reference at their
    centres (n.v, roughness) of about (0.5, 0.5), (0.9, 0.75), (0.25, 1)."""
    _, out, _ = probe_export
    png = cv2.imread(str(out / "brdf_lut.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.shape == (128, 128, 3)
    table = png[..., [2, 1]] / 65535.0  # red scale, green bias
    data = (out / "brdf_lut.ktx2").read_bytes()
    f = parse_ktx2(data)
    assert (f["vkFormat"], f["faceCount"], f["levelCount"], f["pixelHeight"]) == (83, 1, 1, 128)  # R16G16_SFLOAT, 2D
    half = ktx2_levels(f, data, 2)[0][0]
    assert np.allclose(half, table, atol=1e-3)
    for col, row in [(63, 63), (115, 95), (31, 127)]:
        reference = split_sum_quadrature((col + 0.5) / 128, (row + 0.5) / 128)
        assert np.allclose(table[row, col], reference, rtol=0.01, atol=2e-5), (row, col, table[row, col], reference)
    assert np.allclose(brdf_lut(8, 64)[0, -1], [0.99, 0.0], atol=0.02)  # a mirror at normal incidence: F0 alone


def read_sh_txt(path: Path) -> np.ndarray:
    """sh.txt as Filament's samples read it: each line's "(%f,%f,%f)"."""
    values = [re.match(r"\(\s*([-\d.e+]+),\s*([-\d.e+]+),\s*([-\d.e+]+)\)", line).groups()
              for line in path.read_text().splitlines()]
    assert len(values) == 9
    return np.array(values, dtype=np.float64)


def filament_shader(sh: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Filament's irradiance from its pre-scaled SH (light_indirect.fs, Irradiance_SphericalHarmonics)."""
    x, y, z = n[..., 0:1], n[..., 1:2], n[..., 2:3]
    return (sh[0] + sh[1] * y + sh[2] * z + sh[3] * x + sh[4] * (y * x) + sh[5] * (y * z) + sh[6] * (3 * z * z - 1)
            + sh[7] * (z * x) + sh[8] * (x * x - y * y))


def test_sh_txt_of_a_constant_light(tmp_path):
    constant = np.array([0.5, 1.0, 2.0], dtype=np.float32)
    probe = np.where(anglemap_disk_mask(64)[..., None], constant, 0.0).astype(np.float32)
    write_exr(tmp_path / "c.exr", probe)
    export_maps(load_source(tmp_path / "c.exr"), ["filament"], tmp_path, size=16)
    sh = read_sh_txt(tmp_path / "sh.txt")
    # radiance c gives E = pi c; Filament's pre-scaled SH hold E / pi in the constant term alone
    assert np.allclose(sh[0], constant, rtol=1e-4) and np.all(np.abs(sh[1:]) <= 1e-5 * constant)  # the disk's texel grid
    record = json.loads((tmp_path / "sh.json").read_text())
    assert np.allclose(record["coefficients"][0], constant * 2 * np.sqrt(np.pi), rtol=1e-4)  # L_00 = c 2 sqrt(pi)
    assert record["order"][1] == "(1,-1)" and "+y up" in record["convention"]


@pytest.fixture(scope="module")
def courtyard_64():
    return to_layout(read_hdr(ASSETS / "envmaps" / "courtyard.exr"), "anglemap", 64)


def test_sh_txt_of_a_real_probe_is_arsims_band_limited_irradiance(tmp_path, courtyard_64):
    """Filament's shader formula on sh.txt of a bundled probe gives arsim's irradiance map of bands 0-2 (the sh
    method at order 3, its own code path: the maps store E / pi) within 0.1 %."""
    write_exr(tmp_path / "p.exr", courtyard_64)
    export_maps(load_source(tmp_path / "p.exr"), ["filament"], tmp_path, size=16)
    inside = anglemap_disk_mask(64)
    filament = filament_shader(read_sh_txt(tmp_path / "sh.txt"), anglemap_directions(64)[inside])
    arsim_map = sh_maps(courtyard_64, [1.0], 3)[0][inside]
    assert np.allclose(filament, arsim_map, rtol=1e-3, atol=1e-3 * arsim_map.mean())


def test_sh_txt_against_the_accurate_irradiance_map(tmp_path):
    """On a light of bands 0-2 (a smooth sky; a real probe's irradiance has bands 4, 6, ... that nine coefficients
    cannot hold: README), Filament's formula on sh.txt is the accurate method's irradiance map at exponent 1 within
    1 % at every texel; two skies with terms odd in x, y and z, so that a mirrored or swapped axis would show."""
    inside = anglemap_disk_mask(64)
    d = anglemap_directions(64)
    for sky in (lambda x, y, z: 1.0 + 0.6 * y + 0.3 * x * z - 0.2 * z + 0.25 * (x * x - y * y) + 0.4 * x,
                lambda x, y, z: 1.0 + 0.6 * y + 0.3 * (-z) * x - 0.2 * x + 0.25 * (z * z - y * y) - 0.4 * z):
        probe = np.where(inside[..., None], sky(d[..., 0:1], d[..., 1:2], d[..., 2:3]) * np.array([1.0, 0.8, 0.6]), 0.0)
        write_exr(tmp_path / "s.exr", probe.astype(np.float32))
        export_maps(load_source(tmp_path / "s.exr"), ["filament"], tmp_path, size=16)
        filament = filament_shader(read_sh_txt(tmp_path / "sh.txt"), d[inside])
        accurate = accurate_maps(probe.astype(np.float32), [1.0])[0][inside]
        assert np.allclose(filament, accurate, rtol=0.01)


def test_gltf_scene_loads_with_the_extension(probe_export):
    _, out, _ = probe_export
    gltf = pygltflib.GLTF2().load(str(out / "gltf" / "ibl.gltf"))
    assert "EXT_lights_image_based" in gltf.extensionsUsed
    light = gltf.extensions["EXT_lights_image_based"]["lights"][0]
    assert gltf.scenes[gltf.scene].extensions["EXT_lights_image_based"] == {"light": 0}
    coefficients = np.array(light["irradianceCoefficients"])
    assert coefficients.shape == (9, 3) and light["rotation"] == [0.0, 0.0, 0.0, 1.0] and light["intensity"] == 1.0
    assert light["specularImageSize"] == 32 and len(light["specularImages"]) == 4
    assert all(len(level) == 6 for level in light["specularImages"])
    sh = read_sh_txt(out / "sh.txt")  # E_lm = A_l L_lm and Filament's E_lm / pi times the basis constants agree
    assert np.allclose(coefficients[0] / np.pi * 0.5 / np.sqrt(np.pi), sh[0], rtol=1e-6)
    for p, level in enumerate(light["specularImages"]):
        for face, index in enumerate(level):
            image = cv2.imread(str(out / "gltf" / gltf.images[index].uri), cv2.IMREAD_UNCHANGED)
            assert image.shape == (32 >> p, 32 >> p, 4)  # RGBA: RGBD-packed HDR
    # RGBD decodes back to the chain's level 1 (8 bits: within 3 % where it matters)
    data = (out / "specular_ggx.ktx2").read_bytes()
    chain1 = ktx2_levels(parse_ktx2(data), data, 4)[1][..., :3]
    decoded = []
    for face, index in enumerate(light["specularImages"][1]):
        bgra = cv2.imread(str(out / "gltf" / gltf.images[index].uri), cv2.IMREAD_UNCHANGED) / 255.0
        decoded.append(bgra[..., [2, 1, 0]] ** 2.2 / bgra[..., 3:4])
    assert np.median(np.abs(np.stack(decoded) - chain1) / chain1) < 0.03
    meshes = {m.name for m in gltf.meshes}
    assert meshes == {"diffuse", "rough metal", "mirror"} and len(gltf.materials) == 3
    assert (out / "gltf" / gltf.buffers[0].uri).stat().st_size == gltf.buffers[0].byteLength


def test_bake_folder_phong_chain_faces_and_equirects(tmp_path, courtyard_64):
    """A bake's maps as one KTX2 mip chain, the largest exponent at level 0, and as faces and equirects; its
    environment found from its bake.json."""
    write_exr(tmp_path / "env.exr", courtyard_64)
    exponents = [1.0, 10.0, 80.0]
    maps = np.stack([courtyard_64 * k for k in (1.0, 2.0, 3.0)])
    bake = tmp_path / "maps"
    bake.mkdir()
    write_bake(bake, exponents, "fast", MapParameters(), BakeResult(maps, 0.0, (0.0,) * 3), "env.exr")
    out = tmp_path / "out"
    out.mkdir()
    export_maps(load_source(bake), ["ktx2", "faces", "equirect"], out, size=16)
    data = (out / "phong.ktx2").read_bytes()
    f = parse_ktx2(data)
    assert f["kv"]["arsim.phongExponents"] == b"80 10 1\x00" and f["levelCount"] == 3 and f["pixelWidth"] == 16
    levels = ktx2_levels(f, data, 4)
    for p, scale in enumerate((3.0, 2.0, 1.0)):  # level 0 the sharpest map (exponent 80)
        assert np.allclose(levels[p][..., :3], to_cube(courtyard_64 * scale, 16 >> p), rtol=2.0**-10)
    assert (out / "irradiance.ktx2").is_file() and (out / "specular_ggx.ktx2").is_file()
    faces = sorted(p.name for p in (out / "faces").iterdir())
    assert len(faces) == 4 * 6 and "radiance_px.exr" in faces and "reflection_s80_nz.exr" in faces
    assert np.allclose(read_hdr(out / "faces" / "irradiance_py.exr"), to_cube(courtyard_64, 16)[2])
    assert read_hdr(out / "equirect" / "reflection_s10.exr").shape == (32, 64, 3)


def test_faces_follow_the_gl_table():
    """(A check of the table the files rest on: the +Z face's s runs along +x, its t along -y.)"""
    assert CUBE_FACES[4] == ((0, 0, 1), (1, 0, 0), (0, -1, 0)) and np.allclose(level_roughness(5), [0, 0.25, 0.5, 0.75, 1])


def arsim(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "arsim", *map(str, args)], capture_output=True, text=True, cwd=cwd)


def assert_one_line_error(result, fragment):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr and fragment in lines[0], result.stderr


def test_bad_inputs_in_one_line(tmp_path):
    cv2.imwrite(str(tmp_path / "ldr.png"), np.zeros((8, 16, 3), np.uint8))
    assert_one_line_error(arsim("export", tmp_path / "ldr.png", "-o", tmp_path / "o1", "--format", "ktx2"), "not HDR")
    spot_probe([1, 0, 0], 16, tmp_path / "p.exr")
    assert_one_line_error(arsim("export", tmp_path / "p.exr", "-o", tmp_path / "o2", "--format", "ktx2,dds"), "'dds' is unknown")
    bake = tmp_path / "maps"
    bake.mkdir()
    maps = np.stack([spot_probe([1, 0, 0], 16)] * 2)
    write_bake(bake, [1.0, 10.0], "fast", MapParameters(), BakeResult(maps, 0.0, (0.0,) * 2), "p.exr")
    (bake / "reflection_s10.exr").unlink()
    assert_one_line_error(arsim("export", bake, "-o", tmp_path / "o3", "--format", "filament"), "reflection_s10.exr")
    (bake / "bake.json").unlink()
    assert_one_line_error(arsim("export", bake, "-o", tmp_path / "o4", "--format", "filament"), "bake.json")
    assert not any((tmp_path / f"o{k}").exists() for k in range(1, 5))


def test_command_line_writes_the_formats(tmp_path):
    spot_probe([0, 1, 0], 64, tmp_path / "p.exr")
    r = arsim("export", tmp_path / "p.exr", "-o", tmp_path / "out", "--format", "filament,equirect", "--size", "16",
              "--image", "hdr")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "sh.txt").is_file() and read_hdr(tmp_path / "out" / "equirect" / "radiance.hdr").shape == (32, 64, 3)


def test_b10g11r11_texels_and_descriptor():
    """The packed format: red in bits 0-10, green 11-21 (11-bit floats), blue 22-31 (10-bit), a half float's
    exponent; the DFD's samples say so (unsigned floats)."""
    from arsim.core.ktx2 import ktx2_bytes

    cube = np.zeros((6, 2, 2, 3))
    cube[0, 0, 0] = [1.0, 0.5, 2.0]
    cube[0, 0, 1] = [-3.0, 1e9, 65024.0]
    data = ktx2_bytes([cube], "b10g11r11")
    f = parse_ktx2(data)
    assert (f["vkFormat"], f["typeSize"], f["dfd"]["bytesPlane"][0]) == (122, 4, 4)
    assert [(s["channel"], s["bitOffset"], s["bitLength"], s["qualifiers"], s["lower"]) for s in f["dfd"]["samples"]] == \
        [(0, 0, 11, 0x80, 0), (1, 11, 11, 0x80, 0), (2, 22, 10, 0x80, 0)]
    offset, length, _ = f["levels"][0]
    words = np.frombuffer(data, "<u4", count=length // 4, offset=offset)
    assert length == 6 * 4 * 4 and offset % 4 == 0

    def unpack(word):  # exponent bias 15, as the Vulkan specification's unsigned 11- and 10-bit floats
        values = []
        for shift, mantissa_bits in ((0, 6), (11, 6), (22, 5)):
            bits = (int(word) >> shift) & ((1 << (5 + mantissa_bits)) - 1)
            e, m = bits >> mantissa_bits, bits & ((1 << mantissa_bits) - 1)
            values.append(2.0 ** (e - 15) * (1 + m / 2**mantissa_bits) if e else 2.0**-14 * m / 2**mantissa_bits)
        return values

    assert unpack(words[0]) == [1.0, 0.5, 2.0]
    assert unpack(words[1]) == [0.0, 65024.0, 64512.0]  # negatives 0; brighter than the largest finite: the largest
    assert unpack(words[2]) == [0.0, 0.0, 0.0]


def test_filament_sh_from_a_bake_without_its_probe(tmp_path):
    """A bake whose probe cannot be found: sh.txt from its irradiance map (bands 0-2 of E / pi are A_l L_lm / pi)
    equals sh.txt from the probe within 0.5 %; formats that need the radiance are refused in one line."""
    inside = anglemap_disk_mask(32)
    d = anglemap_directions(32)
    probe = np.where(inside[..., None], (1.0 + 0.6 * d[..., 1:2] + 0.3 * d[..., 0:1] * d[..., 2:3] - 0.4 * d[..., 2:3])
                     * np.array([1.0, 0.8, 0.6]), 0.0).astype(np.float32)
    write_exr(tmp_path / "p.exr", probe)
    export_maps(load_source(tmp_path / "p.exr"), ["filament"], tmp_path, size=16)
    from_probe = read_sh_txt(tmp_path / "sh.txt")
    bake = tmp_path / "maps"
    bake.mkdir()
    write_bake(bake, [1.0], "accurate", MapParameters(), BakeResult(accurate_maps(probe, [1.0]), 0.0, (0.0,)), "gone.exr")
    out = tmp_path / "out"
    out.mkdir()
    source = load_source(bake)
    assert source.radiance is None and "gone.exr" in source.missing
    export_maps(source, ["filament"], out)
    assert np.allclose(read_sh_txt(out / "sh.txt"), from_probe, rtol=0.005, atol=0.005 * from_probe[0].max())
    assert json.loads((out / "sh.json").read_text())["from"] == "the bake's irradiance map"
    r = arsim("export", bake, "-o", tmp_path / "o", "--format", "filament,gltf")
    assert_one_line_error(r, "gltf needs the radiance")
    assert not (tmp_path / "o").exists()


def test_a_gl_sampler_reads_the_skybox_in_world_directions(tmp_path):
    """The skybox file's faces uploaded as they are to an OpenGL cube map (moderngl) and sampled with world
    directions give the probe's light from those directions: no axis is mirrored (red 2 + x, green 2 + y, blue
    2 + z would show any flip as an error of up to 100 %)."""
    from arsim.core.gl import create_gl_context
    from arsim.core.resample import sample_anglemap

    d = anglemap_directions(64)
    probe = np.where(anglemap_disk_mask(64)[..., None], 2.0 + d, 0.0).astype(np.float32)
    write_exr(tmp_path / "p.exr", probe)
    out = tmp_path / "out"
    out.mkdir()
    export_maps(load_source(tmp_path / "p.exr"), ["ktx2"], out, size=32)
    data = (out / "skybox.ktx2").read_bytes()
    faces = ktx2_levels(parse_ktx2(data), data, 4)[0]
    ctx = create_gl_context()
    try:
        texture = ctx.texture_cube((32, 32), 4, data=faces.astype("f4").tobytes(), dtype="f4")
        texture.filter = (ctx.LINEAR, ctx.LINEAR)
        rng = np.random.default_rng(3)
        directions = rng.normal(size=(256, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        source = ctx.buffer(np.concatenate([directions, np.zeros((256, 1))], axis=1).astype("f4").tobytes())
        result = ctx.buffer(reserve=256 * 16)
        shader = ctx.compute_shader("""
            #version 430
            layout(local_size_x = 64) in;
            layout(std430, binding = 0) readonly buffer Directions { vec4 d[]; };
            layout(std430, binding = 1) writeonly buffer Values { vec4 v[]; };
            uniform samplerCube cube;
            void main() { uint i = gl_GlobalInvocationID.x; v[i] = texture(cube, d[i].xyz); }
        """)
        texture.use(0)
        shader["cube"] = 0
        source.bind_to_storage_buffer(0)
        result.bind_to_storage_buffer(1)
        shader.run(256 // 64)
        sampled = np.frombuffer(result.read(), dtype="f4").reshape(256, 4)[:, :3]
    finally:
        ctx.release()
    assert np.allclose(sampled, 2.0 + directions, atol=0.04)
    assert np.allclose(sampled, sample_anglemap(probe, directions), atol=0.04)


@pytest.fixture(scope="module")
def fuzz_inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz_inputs")
    spot_probe([0, 0, 1], 16, folder / "p.exr")
    cv2.imwrite(str(folder / "a.png"), np.zeros((8, 8, 3), np.uint8))
    bake = folder / "maps"
    bake.mkdir()
    write_bake(bake, [1.0, 10.0], "fast", MapParameters(), BakeResult(np.stack([spot_probe([0, 0, 1], 16)] * 2), 0.0, (0.0,) * 2),
               "nowhere.exr")
    return {"probe": str(folder / "p.exr"), "png": str(folder / "a.png"), "maps": str(bake), "none": str(folder / "nosuch.exr"),
            "folder": str(folder)}


def test_fuzzed_export_command_lines_export_or_are_refused_in_one_line(fuzz_inputs, tmp_path_factory):
    """Inputs (a probe, a bake without its probe, an 8-bit image, a missing file, a folder that is not a bake) and
    options drawn at random: each command writes its output or is refused in one line, leaving nothing behind."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from tests.fuzzing import check_command

    good = [fuzz_inputs["probe"], fuzz_inputs["maps"]] * 3  # drawn more often: some command lines must get through
    paths = st.sampled_from(good + sorted(fuzz_inputs.values()) + ["", "a\x00b"])
    options = {"--format": st.sampled_from(["ktx2", "filament", "gltf,faces", "equirect,filament", "faces", "filament,ktx2",
                                            "ktx3", ",", "", "KTX2,ktx2"]),
               "--size": st.sampled_from(["16", "32", "8", "100", "x", "0", "-16", "4096", ""]),
               "--image": st.sampled_from(["exr", "hdr", "png", "jpg"]), "--texel": st.sampled_from(["rgba16f", "b10g11r11", "x"]),
               "--env": paths}

    seen = []

    @settings(max_examples=60, deadline=None, derandomize=True, database=None)
    @given(source=paths, names=st.lists(st.sampled_from(sorted(options)), unique=True, max_size=4), data=st.data())
    def run(source, names, data):
        argv = ["export", source, f"--format={data.draw(options['--format'])}"]
        argv += [f"{name}={data.draw(options[name])}" for name in names if name != "--format"]
        seen.append(check_command(argv, tmp_path_factory.mktemp("cmd") / "out"))

    run()
    assert seen.count("ok") >= 3 and seen.count("refused") >= 10, seen  # (both kinds were drawn)
