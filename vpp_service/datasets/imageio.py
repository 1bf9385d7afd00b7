"""Reading benchmark images, masks and integer-coded disparity maps from disk."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def _imread(path: str | Path, what: str) -> np.ndarray:
    """Read ``path`` as stored (``cv2.IMREAD_UNCHANGED``); ``what`` names it in errors."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: {what} not found: {path}")
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise ValueError(f"path: cannot decode {what} {path}")
    return raw


def read_image(path: str | Path) -> np.ndarray:
    """Read an 8-bit image as stored: H x W (gray) or H x W x 3 RGB, uint8.

    Parameters
    ----------
    path : str or Path
        PNG / PPM / PGM / JPEG file.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If OpenCV cannot decode it or it is not 8-bit.
    """
    img = _imread(path, "image")
    if img.dtype != np.uint8:
        raise ValueError(f"path: expected an 8-bit image, {path} is {img.dtype}")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB) if img.shape[2] == 3 else img[..., 0]
    return np.ascontiguousarray(img)


def read_scaled_disparity(path: str | Path, scale: float) -> np.ndarray:
    """Read an integer-coded disparity map (PNG/PGM, 8 or 16 bit) and decode it.

    Parameters
    ----------
    path : str or Path
        Disparity image; value 0 means "no ground truth".
    scale : float
        Divisor: disparity = value / scale (> 0).

    Returns
    -------
    ndarray
        H x W float32 disparity, NaN where the stored value is 0.
    """
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale: must be a finite number > 0, got {scale!r}")
    raw = _imread(path, "disparity image")
    if raw.ndim == 3:
        raw = raw[..., 0]
    disp = raw.astype(np.float32) / np.float32(scale)
    disp[raw == 0] = np.nan
    return disp


def read_mask(path: str | Path, threshold: int = 128) -> np.ndarray:
    """Read a mask image; True where the (first channel) value is >= ``threshold``.

    Middlebury ``mask0nocc.png`` / ``nonocc.png`` use 255 for non-occluded pixels
    (128 = occluded, 0 = invalid), hence the default threshold.
    """
    raw = _imread(path, "mask")
    if raw.ndim == 3:
        raw = raw[..., 0]
    return raw >= threshold


__all__ = ["read_image", "read_mask", "read_scaled_disparity"]
