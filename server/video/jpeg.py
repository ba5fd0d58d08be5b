"""JPEG frames: a cheap check of what a camera posts, and the encoder the replay uses.

:func:`jpeg_size` reads the frame size from the JPEG's start-of-frame marker without
decoding the picture (a 1280 x 720 decode costs milliseconds; the walk costs
microseconds), and refuses what is not a complete baseline or progressive JPEG: no
start-of-image marker, no frame header, or no end-of-image marker (a truncated upload).
"""

from __future__ import annotations

import numpy as np

from demtrack.core.errors import VideoError

__all__ = ["encode_jpeg", "jpeg_size"]

# Start-of-frame markers (0xC0..0xCF less DHT 0xC4, JPG 0xC8, DAC 0xCC).
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# Markers without a length field.
_BARE = frozenset({0x01, *range(0xD0, 0xD8)})


def jpeg_size(data: bytes) -> tuple[int, int]:
    """``(width, height)`` in pixels of a JPEG, from its frame header.

    Raises
    ------
    VideoError
        One line: not a JPEG, no frame header, or truncated (no end-of-image marker).
    """
    n = len(data)
    if n < 4 or data[0] != 0xFF or data[1] != 0xD8:
        raise VideoError(f"frame is not a JPEG (no start-of-image marker; {n} bytes)")
    end = n
    while end > 2 and data[end - 1] == 0:  # some encoders pad after the end marker
        end -= 1
    if data[end - 2 : end] != b"\xff\xd9":
        raise VideoError("frame is a truncated JPEG (no end-of-image marker)")
    i = 2
    while i + 4 <= end:
        if data[i] != 0xFF:
            raise VideoError(f"frame is a damaged JPEG (no marker at byte {i})")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _BARE:
            i += 2
            continue
        length = (data[i + 2] << 8) | data[i + 3]
        if length < 2 or i + 2 + length > end:
            raise VideoError(f"frame is a damaged JPEG (segment at byte {i} runs past the end)")
        if marker in _SOF:
            if length < 7:
                raise VideoError("frame is a damaged JPEG (short frame header)")
            height = (data[i + 5] << 8) | data[i + 6]
            width = (data[i + 7] << 8) | data[i + 8]
            if width == 0 or height == 0:
                raise VideoError(f"frame is a JPEG of {width}x{height} pixels")
            return width, height
        if marker == 0xDA:  # start of scan before any frame header
            break
        i += 2 + length
    raise VideoError("frame is a damaged JPEG (no frame header)")


def encode_jpeg(image: np.ndarray, *, max_width: int = 1280, quality: int = 75) -> bytes:
    """JPEG bytes of an RGB ``(h, w, 3)`` or grey ``(h, w)`` uint8 image.

    Wider than ``max_width`` pixels: downscaled (area interpolation) to that width, the
    aspect kept; ``quality`` is the JPEG quality (1..100).
    """
    import cv2

    img = np.asarray(image)
    if img.ndim == 3:
        img = img[:, :, ::-1]  # OpenCV writes BGR
    h, w = img.shape[:2]
    if w > max_width:
        size = (int(max_width), max(1, round(h * max_width / w)))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise VideoError("cannot encode the frame as JPEG")
    return buf.tobytes()
