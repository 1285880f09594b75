"""Integrity of the image files of a folder recording, before they are decoded.

A decoder alone does not notice every damaged file: OpenCV returns a truncated PNG or JPEG
with its missing rows filled in, and a PNG's decoder may skip a flipped bit that its chunk
checksums would have shown. So every PNG is checked here: signature, every chunk's CRC-32,
the header (IHDR) first and the end (IEND) present, the compressed image data complete
(zlib's own Adler-32 checked) and of the size the header implies. A JPEG carries no
checksum: only its start and end markers are checked (a truncated file has no end marker);
a flipped bit inside a JPEG cannot be detected.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type -> samples per pixel
PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
#: Adam7 passes: (x start, y start, x step, y step)
ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
         (0, 1, 1, 2))  # fmt: skip


def _scanline_bytes(width: int, height: int, bits_per_pixel: int, interlaced: bool) -> int:
    """Bytes of the filtered image data (one filter byte per row) of a PNG."""

    def rows(w: int, h: int) -> int:
        return 0 if w == 0 or h == 0 else h * (1 + (w * bits_per_pixel + 7) // 8)

    if not interlaced:
        return rows(width, height)
    return sum(
        rows((width - x0 + dx - 1) // dx, (height - y0 + dy - 1) // dy) for x0, y0, dx, dy in ADAM7
    )


def png_damage(data: bytes) -> str | None:
    """Why ``data`` is not an intact PNG (one phrase), or None when it is."""
    if not data.startswith(PNG_SIGNATURE):
        return "not a PNG file (its first 8 bytes are not the PNG signature)"
    pos, idat, header = len(PNG_SIGNATURE), [], None
    while True:
        if pos + 8 > len(data):
            return f"truncated at byte {len(data)} (the file ends before its IEND chunk)"
        length, ctype = struct.unpack(">I4s", data[pos : pos + 8])
        name = ctype.decode("latin-1")
        end = pos + 12 + length
        if end > len(data):
            return f"truncated at byte {len(data)} (inside its {name!r} chunk at byte {pos})"
        if zlib.crc32(data[pos + 4 : end - 4]) != int.from_bytes(data[end - 4 : end], "big"):
            return f"damaged: checksum (CRC) error in its {name!r} chunk at byte {pos}"
        if header is None and ctype != b"IHDR":
            return f"damaged: the first chunk is {name!r}, not IHDR"
        if ctype == b"IHDR":
            if length != 13:
                return f"damaged: IHDR chunk of {length} bytes, not 13"
            header = struct.unpack(">IIBBBBB", data[pos + 8 : pos + 21])
        elif ctype == b"IDAT":
            idat.append(data[pos + 8 : end - 4])
        elif ctype == b"IEND":
            break
        pos = end
    width, height, depth, colour, _, _, interlace = header
    if colour not in PNG_CHANNELS or depth not in (1, 2, 4, 8, 16) or interlace not in (0, 1):
        return f"damaged: invalid header (bit depth {depth}, colour type {colour})"
    inflater = zlib.decompressobj()
    try:
        raw = len(inflater.decompress(b"".join(idat)))
    except zlib.error as exc:
        return f"damaged: its compressed image data does not decompress ({exc})"
    if not inflater.eof:
        return "truncated: its compressed image data ends early"
    want = _scanline_bytes(width, height, depth * PNG_CHANNELS[colour], bool(interlace))
    if raw != want:
        return f"damaged: {raw} bytes of image data, but its {width}x{height} header needs {want}"
    return None


def jpeg_damage(data: bytes) -> str | None:
    """Why ``data`` is not a complete JPEG (start and end markers), or None."""
    if not data.startswith(b"\xff\xd8"):
        return "not a JPEG file (no start-of-image marker)"
    if b"\xff\xd9" not in data[-64:]:
        return "truncated (no end-of-image marker at the end of the file)"
    return None


def image_damage(path: Path, data: bytes) -> str | None:
    """Why the image file ``path`` (its bytes ``data``) is damaged, or None; by its suffix
    (.png, .jpg/.jpeg)."""
    if not data:
        return "empty file (0 bytes)"
    if path.suffix.lower() == ".png":
        return png_damage(data)
    return jpeg_damage(data)
