"""KTX 2.0 texture files (Khronos KTX File Format Specification 2.0), written without supercompression: 2D
textures and cube maps with their mip levels, in half floats (VK_FORMAT_R16G16B16A16_SFLOAT, R16G16_SFLOAT) or
packed unsigned floats (VK_FORMAT_B10G11R11_UFLOAT_PACK32).

The file, in order: the 12-byte identifier; the header (vkFormat, typeSize, pixelWidth, pixelHeight, pixelDepth,
layerCount, faceCount, levelCount, supercompressionScheme); the index (the data format descriptor's and the
key/value data's offsets and lengths; no supercompression global data); the level index (offset, length and
uncompressed length of each level, level 0 first); the data format descriptor (its total size, then one basic
descriptor block: the RGBSDA colour model, BT.709 primaries, linear transfer, one sample per channel); the
key/value data (sorted by key, each entry padded to 4 bytes); then the levels, the smallest first (so that a
streaming reader can show something early), each starting on a multiple of lcm(texel size, 4) bytes. Within
a level the faces follow each other in the order +X, -X, +Y, -Y, +Z, -Z, each face's rows top first (KTX2's
orientation "rd", and OpenGL's and Vulkan's cube-map convention: core.conventions.CUBE_FACES).
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from arsim.core.errors import ArsimError
from arsim.core.files import write_bytes_atomic

IDENTIFIER = b"\xabKTX 20\xbb\r\n\x1a\n"  # «KTX 20»\r\n\x1a\n

VK_FORMAT_R16G16_SFLOAT = 83
VK_FORMAT_R16G16B16A16_SFLOAT = 97
VK_FORMAT_B10G11R11_UFLOAT_PACK32 = 122

# Khronos Data Format Specification 1.3: the basic descriptor block's enumerations
KHR_DF_MODEL_RGBSDA = 1
KHR_DF_PRIMARIES_BT709 = 1
KHR_DF_TRANSFER_LINEAR = 1
KHR_DF_VERSION = 2
KHR_DF_SAMPLE_DATATYPE_FLOAT = 0x80
KHR_DF_SAMPLE_DATATYPE_SIGNED = 0x40
CHANNEL_IDS = {"R": 0, "G": 1, "B": 2, "A": 15}
FLOAT_ONE, FLOAT_MINUS_ONE = 0x3F800000, 0xBF800000  # a float sample's lower and upper: -1.0 (or 0) and 1.0

HALF_MAX = 65504.0  # the largest finite half float: brighter texels are clamped to it, not turned to infinity


def _pack_half(channels: int) -> Callable[[np.ndarray], bytes]:
    def pack(texels: np.ndarray) -> bytes:
        values = np.asarray(texels, dtype=np.float64)
        if values.shape[-1] < channels:  # RGB stored as RGBA: alpha 1
            values = np.concatenate([values, np.ones(values.shape[:-1] + (channels - values.shape[-1],))], axis=-1)
        return np.clip(values[..., :channels], -HALF_MAX, HALF_MAX).astype("<f2").tobytes()
    return pack


def _pack_b10g11r11(texels: np.ndarray) -> bytes:
    """Red and green as 11-bit, blue as 10-bit unsigned floats (5-bit exponent with a half float's bias, 6 or 5
    bits of mantissa) in one little-endian 32-bit word, red in the low bits: a half float's bits shifted right,
    rounded to nearest, negatives as 0, the largest finite value where a texel is brighter."""
    half = np.clip(np.asarray(texels, dtype=np.float64)[..., :3], 0.0, HALF_MAX).astype("<f2").view(np.uint16).astype(np.uint32)
    r = np.minimum((half[..., 0] + 0x8) >> 4, 0x7BF)  # 0x7BF: exponent 30, mantissa 63, the largest finite 11-bit float
    g = np.minimum((half[..., 1] + 0x8) >> 4, 0x7BF)
    b = np.minimum((half[..., 2] + 0x10) >> 5, 0x3DF)
    return (r | (g << 11) | (b << 22)).astype("<u4").tobytes()


@dataclass(frozen=True)
class Format:
    """A texel format: its VkFormat, typeSize, bytes per texel and the data format descriptor's samples
    (channel, bit offset, bit length, qualifier flags, lower, upper)."""

    name: str
    vk_format: int
    type_size: int
    texel_bytes: int
    samples: tuple[tuple[str, int, int, int, int, int], ...]
    pack: Callable[[np.ndarray], bytes]


_SF = KHR_DF_SAMPLE_DATATYPE_FLOAT | KHR_DF_SAMPLE_DATATYPE_SIGNED
FORMATS = {
    "rgba16f": Format("rgba16f", VK_FORMAT_R16G16B16A16_SFLOAT, 2, 8,
                      tuple((c, 16 * i, 16, _SF, FLOAT_MINUS_ONE, FLOAT_ONE) for i, c in enumerate("RGBA")), _pack_half(4)),
    "rg16f": Format("rg16f", VK_FORMAT_R16G16_SFLOAT, 2, 4,
                    tuple((c, 16 * i, 16, _SF, FLOAT_MINUS_ONE, FLOAT_ONE) for i, c in enumerate("RG")), _pack_half(2)),
    "b10g11r11": Format("b10g11r11", VK_FORMAT_B10G11R11_UFLOAT_PACK32, 4, 4,
                        (("R", 0, 11, KHR_DF_SAMPLE_DATATYPE_FLOAT, 0, FLOAT_ONE),
                         ("G", 11, 11, KHR_DF_SAMPLE_DATATYPE_FLOAT, 0, FLOAT_ONE),
                         ("B", 22, 10, KHR_DF_SAMPLE_DATATYPE_FLOAT, 0, FLOAT_ONE)), _pack_b10g11r11),
}


def data_format_descriptor(fmt: Format) -> bytes:
    """The DFD: dfdTotalSize, then one basic descriptor block (Khronos Data Format Specification, section 5)."""
    block_size = 24 + 16 * len(fmt.samples)
    block = struct.pack("<IHHBBBB4B8B",
                        0,  # vendorId 0 (Khronos, low 17 bits), descriptorType 0 (basic, high 15 bits)
                        KHR_DF_VERSION, block_size,
                        KHR_DF_MODEL_RGBSDA, KHR_DF_PRIMARIES_BT709, KHR_DF_TRANSFER_LINEAR, 0,  # flags: straight alpha
                        0, 0, 0, 0,  # texelBlockDimension0-3: 1 x 1 x 1 x 1, stored as value - 1
                        fmt.texel_bytes, 0, 0, 0, 0, 0, 0, 0)  # bytesPlane0-7
    for channel, offset, length, qualifiers, lower, upper in fmt.samples:
        block += struct.pack("<HBB4BII", offset, length - 1, CHANNEL_IDS[channel] | qualifiers, 0, 0, 0, 0, lower, upper)
    return struct.pack("<I", 4 + len(block)) + block


def key_value_data(items: Mapping[str, str | bytes]) -> bytes:
    """Key/value entries sorted by key: keyAndValueByteLength, the key and its NUL, the value (a string gets
    its NUL), zero padding to 4 bytes."""
    out = b""
    for key in sorted(items, key=lambda k: k.encode("utf-8")):
        value = items[key]
        value = value.encode("utf-8") + b"\x00" if isinstance(value, str) else bytes(value)
        entry = key.encode("utf-8") + b"\x00" + value
        out += struct.pack("<I", len(entry)) + entry + b"\x00" * (-len(entry) % 4)
    return out


def ktx2_bytes(levels: Sequence[np.ndarray], fmt: str = "rgba16f", key_values: Mapping[str, str | bytes] | None = None) -> bytes:
    """A KTX2 file of a 2D texture or a cube map: levels[p] is mip level p, (faces, height, width, channels)
    with faces 1 (2D) or 6 (cube map, in the order +X, -X, +Y, -Y, +Z, -Z), each level half the one before
    (rounded down, at least 1). key_values are added to KTXorientation ("rd") and KTXwriter."""
    if fmt not in FORMATS:
        raise ArsimError(f"KTX2 format {fmt!r} is unknown; use one of {', '.join(FORMATS)}")
    f = FORMATS[fmt]
    if not levels:
        raise ArsimError("a KTX2 file needs at least one level")
    faces, height, width = levels[0].shape[:3]
    if faces not in (1, 6) or (faces == 6 and height != width):
        raise ArsimError(f"KTX2: {faces} faces of {width} x {height}; give 1 face, or 6 square ones for a cube map")
    for p, level in enumerate(levels):
        want = (faces, max(1, height >> p), max(1, width >> p))
        if level.shape[:3] != want:
            raise ArsimError(f"KTX2: level {p} is {level.shape[:3]}, not {want}: each level halves the one before")
    if len(levels) > int(math.log2(max(width, height))) + 1:
        raise ArsimError(f"KTX2: {len(levels)} levels for {width} x {height}; at most {int(math.log2(max(width, height))) + 1}")
    from arsim import __version__

    kv = {"KTXorientation": "rd", "KTXwriter": f"arsim {__version__}", **(key_values or {})}
    dfd = data_format_descriptor(f)
    kvd = key_value_data(kv)
    count = len(levels)
    dfd_offset = 12 + 9 * 4 + 4 * 4 + 2 * 8 + count * 3 * 8
    kvd_offset = dfd_offset + len(dfd)
    align = math.lcm(f.texel_bytes, 4)
    data = [f.pack(level) for level in levels]
    offsets = [0] * count
    cursor = kvd_offset + len(kvd)
    body = b""
    for p in reversed(range(count)):  # the smallest level first
        pad = -cursor % align
        body += b"\x00" * pad
        cursor += pad
        offsets[p] = cursor
        body += data[p]
        cursor += len(data[p])
    header = IDENTIFIER + struct.pack("<9I", f.vk_format, f.type_size, width, height, 0, 0, faces, count, 0)
    index = struct.pack("<4I2Q", dfd_offset, len(dfd), kvd_offset if kvd else 0, len(kvd), 0, 0)
    level_index = b"".join(struct.pack("<3Q", offsets[p], len(data[p]), len(data[p])) for p in range(count))
    return header + index + level_index + dfd + kvd + body


def write_ktx2(path: str | os.PathLike, levels: Sequence[np.ndarray], fmt: str = "rgba16f",
               key_values: Mapping[str, str | bytes] | None = None) -> None:
    """Write ktx2_bytes(levels, fmt, key_values) to path, atomically."""
    write_bytes_atomic(path, ktx2_bytes(levels, fmt, key_values))
