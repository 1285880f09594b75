"""The image-file integrity check of folder recordings (``physanim.capture.image_file``): PNGs
written here chunk by chunk, plain and Adam7-interlaced, intact and damaged."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from physanim.capture.image_file import ADAM7, image_damage, png_damage


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png(rgb: np.ndarray, interlace: bool = False, rows: int | None = None) -> bytes:
    """An 8-bit RGB PNG of ``rgb`` (H, W, 3); ``rows``: only that many scanlines of data."""
    h, w = rgb.shape[:2]
    passes = ADAM7 if interlace else ((0, 0, 1, 1),)
    lines = [
        b"\x00" + row.tobytes()
        for x0, y0, dx, dy in passes
        for row in rgb[y0::dy, x0::dx]
        if row.size
    ]
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, int(interlace))
    idat = zlib.compress(b"".join(lines[:rows]))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


RGB = np.random.default_rng(0).integers(0, 256, (37, 53, 3), dtype=np.uint8)


@pytest.mark.parametrize("interlace", [False, True])
def test_intact_png_passes_and_decodes(interlace: bool) -> None:
    data = png(RGB, interlace)
    assert png_damage(data) is None
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(decoded[..., ::-1], RGB)


def test_damaged_pngs_are_named() -> None:
    data = png(RGB)
    flipped = bytearray(data)
    flipped[60] ^= 4  # inside IDAT
    assert "checksum (CRC) error in its 'IDAT' chunk" in png_damage(bytes(flipped))
    assert png_damage(data[:-12]).startswith("truncated at byte")  # IEND cut off
    assert png_damage(data[:60]).startswith("truncated at byte 60 (inside its 'IDAT' chunk")
    assert "not a PNG file" in png_damage(b"GIF89a" + data[6:])
    short = png(RGB, rows=30)  # all checksums right, 7 scanlines missing
    assert png_damage(short) == (
        f"damaged: {30 * (1 + 53 * 3)} bytes of image data, but its 53x37 header needs "
        f"{37 * (1 + 53 * 3)}"
    )
    assert image_damage(Path("x.png"), b"") == "empty file (0 bytes)"


def test_jpeg_end_marker() -> None:
    ok, buf = cv2.imencode(".jpg", RGB)
    data = buf.tobytes()
    assert image_damage(Path("f.jpg"), data) is None
    assert "no end-of-image marker" in image_damage(Path("f.jpg"), data[: len(data) // 2])
