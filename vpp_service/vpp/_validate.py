"""Input validation shared by the VPP wrappers (images, disparity maps); thread counts: :mod:`vpp_service.threads`."""

from __future__ import annotations

import numpy as np


def as_image(name: str, a: object) -> np.ndarray:
    """Validate a uint8 H x W or H x W x C (C in {1, 3}) image; returns a C-contiguous H x W x C view/copy."""
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name} must be a numpy.ndarray, got {type(a).__name__}")
    if a.dtype != np.uint8:
        raise TypeError(f"{name} must have dtype uint8, got {a.dtype}")
    if a.ndim == 2:
        a = a[:, :, None]
    elif a.ndim != 3 or a.shape[2] not in (1, 3):
        raise ValueError(f"{name} must be H x W or H x W x C with C in (1, 3), got shape {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name} must not be empty, got shape {a.shape}")
    return np.ascontiguousarray(a)


def as_disparity(name: str, a: object, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Validate an H x W float32/float64 disparity map; returns C-contiguous float32.

    float64 is converted to float32 (the kernel's key precision).  Values are
    not checked here: 0 / NaN mean "no point"; negative, infinite or too large
    values are counted as invalid by the kernel.
    """
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name} must be a numpy.ndarray, got {type(a).__name__}")
    if a.dtype not in (np.float32, np.float64):
        raise TypeError(f"{name} must have dtype float32 or float64, got {a.dtype}")
    if a.ndim != 2:
        raise ValueError(f"{name} must be 2-D (H x W), got shape {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name} must not be empty, got shape {a.shape}")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} shape {a.shape} does not match the images' {shape}")
    return np.ascontiguousarray(a, dtype=np.float32)
