"""Images on disk: float32 OpenEXR with metadata, and sRGB PNG previews.

Every write goes to a temporary file in the target folder and is renamed into
place, so an interrupted run never leaves a half-written image behind.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile

import numpy as np

#: Header attributes written by OpenEXR itself, not ours.
_EXR_STANDARD = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder",
                 "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type",
                 "version", "chunkCount", "tiles", "name"}


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success."""
    folder = os.path.dirname(os.path.abspath(path))
    stem, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=f".tmp{ext}", dir=folder)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def check_writable(path: str) -> None:
    """Raise OSError early (before any rendering) when ``path`` cannot be written."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(folder):
        raise OSError(f"output folder does not exist: {folder}")
    if not os.access(folder, os.W_OK):
        raise OSError(f"output folder is not writable: {folder}")
    if os.path.isdir(path):
        raise OSError(f"output path is a folder: {path}")


def _as_rgb(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] < 3:
        raise ValueError(f"expected an H x W x 3 image, got shape {image.shape}")
    return np.ascontiguousarray(image[..., :3])


def write_exr(path: str, image: np.ndarray, metadata: dict | None = None) -> None:
    """Write float32 RGB with ``metadata`` as string header attributes (dicts as JSON)."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (metadata or {}).items():
        header[key] = value if isinstance(value, str) else json.dumps(value)
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, {"RGB": _as_rgb(image)}) as exr:
            exr.write(tmp)


def read_exr(path: str) -> tuple[np.ndarray, dict]:
    """(H x W x 3 float32 image, our metadata) from an EXR written by ``write_exr``."""
    import OpenEXR

    with OpenEXR.File(path) as exr:
        channels = exr.channels()
        if "RGB" in channels:
            pixels = np.array(channels["RGB"].pixels, dtype=np.float32)
        else:
            pixels = np.stack([np.array(channels[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
        meta = {k: v for k, v in exr.header().items() if k not in _EXR_STANDARD}
    return pixels, meta


def srgb_preview(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """8-bit sRGB of linear radiance (x 2^exposure), clipped to [0, 1]; the
    transfer function is IEC 61966-2-1 as implemented by colour-science."""
    import colour

    linear = np.clip(_as_rgb(image) * (2.0 ** exposure), 0.0, 1.0)
    encoded = colour.cctf_encoding(linear, function="sRGB")
    return np.round(np.nan_to_num(encoded) * 255.0).astype(np.uint8)


def write_png(path: str, image: np.ndarray, exposure: float = 0.0) -> None:
    """sRGB PNG preview of a linear image (see ``srgb_preview``)."""
    import mitsuba as mi

    bitmap = mi.Bitmap(srgb_preview(image, exposure), pixel_format=mi.Bitmap.PixelFormat.RGB)
    with atomic_path(path) as tmp:
        bitmap.write(tmp, mi.Bitmap.FileFormat.PNG)
