"""Images on disk: float32 OpenEXR with metadata, and sRGB PNG previews.

Every write goes to a temporary file in the target folder and is renamed into
place, so an interrupted run never leaves a half-written image behind; the file
then has the mode an ordinary ``open(path, "w")`` would give it (0o666 less the
umask), not the temporary file's 0o600.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading

import numpy as np

#: Header attributes written by OpenEXR itself, not ours.
_EXR_STANDARD = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder",
                 "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type",
                 "version", "chunkCount", "tiles", "name"}


_UMASK_LOCK = threading.Lock()


def current_umask() -> int:
    """The process umask, read without changing it (Linux: /proc/self/status).

    Elsewhere falls back to setting and restoring it (``os.umask`` has no
    read-only form), under a lock so that two of our threads never race; a
    file created by another thread during that instant gets umask 0o022.
    """
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def default_file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file: 0o666 less the umask."""
    return 0o666 & ~current_umask()


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    The temporary file (created 0o600 by ``mkstemp``) gets the umask's mode
    (``default_file_mode``) just before the rename, whatever the writer did to it.
    """
    folder = os.path.dirname(os.path.abspath(path))
    stem, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=f".tmp{ext}", dir=folder)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, default_file_mode())
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


def ensure_parent(path: str) -> str:
    """Create the folder that will hold ``path`` (and its parents) if missing, then
    ``check_writable(path)``; returns the folder. Raises OSError with one line
    (e.g. when a component of the folder is a file or cannot be created)."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    try:
        os.makedirs(folder, exist_ok=True)
    except FileExistsError:
        raise OSError(f"output folder is a file: {folder}") from None
    except OSError as err:
        raise OSError(f"cannot create output folder {folder}: {err.strerror or err}") from None
    check_writable(path)
    return folder


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
