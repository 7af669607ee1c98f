"""An image's size and kind read from its header, before anything is decoded.

A PNG whose header claims 100000 x 100000 pixels would make a decoder allocate tens of
gigabytes from a file of a few hundred bytes (a decompression bomb). Reading the header first
lets the loaders refuse such a file, or one of the wrong size or kind, without decoding it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_START = b"\xff\xd8"

# PNG colour type -> channels as decoded (a palette decodes to colour)
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}
# JPEG start-of-frame markers: C0-CF except DHT (C4), JPG (C8) and DAC (CC)
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_JPEG_STANDALONE = {0x01, *range(0xD0, 0xD8)}


class HeaderError(ValueError):
    """The bytes do not start with a valid PNG or JPEG header; the text says what is wrong."""


@dataclass(frozen=True)
class ImageHeader:
    """What a header says: ``format`` "png" or "jpeg", size in pixels, channels, bits each."""

    format: str
    width: int
    height: int
    channels: int
    bit_depth: int

    @property
    def pixels(self) -> int:
        return self.width * self.height


def read_header(data: bytes) -> ImageHeader:
    """The header of a PNG or JPEG file's ``data``; raises :class:`HeaderError`."""
    if data.startswith(PNG_SIGNATURE):
        return _png_header(data)
    if data.startswith(JPEG_START):
        return _jpeg_header(data)
    raise HeaderError("not a PNG or JPEG file")


def _png_header(data: bytes) -> ImageHeader:
    if len(data) < 33 or data[12:16] != b"IHDR":
        raise HeaderError("PNG header (IHDR) is missing or truncated")
    length, width, height, bit_depth, colour_type = struct.unpack(">I4xIIBB", data[8:26])
    if length != 13:
        raise HeaderError("PNG header (IHDR) has the wrong length")
    if colour_type not in _PNG_CHANNELS or bit_depth not in (1, 2, 4, 8, 16):
        raise HeaderError(f"PNG colour type {colour_type} / bit depth {bit_depth} is invalid")
    if not (0 < width < 2**31 and 0 < height < 2**31):
        raise HeaderError(f"PNG header claims an invalid size {width} x {height}")
    return ImageHeader("png", width, height, _PNG_CHANNELS[colour_type], bit_depth)


def _jpeg_header(data: bytes) -> ImageHeader:
    at = 2
    while at + 4 <= len(data):
        if data[at] != 0xFF:
            raise HeaderError("JPEG marker expected: the file is corrupt")
        marker = data[at + 1]
        if marker == 0xFF:  # fill byte
            at += 1
            continue
        if marker in _JPEG_STANDALONE:
            at += 2
            continue
        (length,) = struct.unpack(">H", data[at + 2 : at + 4])
        if marker in _JPEG_SOF:
            if length < 8 or at + 10 > len(data):
                raise HeaderError("JPEG frame header is truncated")
            precision, height, width, components = struct.unpack(">BHHB", data[at + 4 : at + 10])
            if width == 0 or height == 0:
                raise HeaderError(f"JPEG header claims an invalid size {width} x {height}")
            return ImageHeader("jpeg", width, height, components, precision)
        if marker == 0xDA or length < 2:
            break
        at += 2 + length
    raise HeaderError("JPEG frame header (SOF) is missing or truncated")
