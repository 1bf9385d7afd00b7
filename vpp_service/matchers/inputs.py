"""The input contract every matcher shares: the checks of images, pairs, disparity maps and hints.

Every matcher, and every kernel wrapper of :mod:`vpp_service.matchers` (holes, border,
speckle, guided), validates its arrays with these before a kernel sees them; each check
raises TypeError (not an array, wrong dtype) or ValueError (shape, emptiness, contiguity,
+-inf) naming the argument. Below :mod:`~vpp_service.matchers.base`, which imports it.
"""

from __future__ import annotations

import cv2
import numpy as np


def check_array(
    a: object, name: str, dtypes: tuple[type, ...], ndim: int | tuple[int, ...], layout: str, *, contiguous: bool = True
) -> np.ndarray:
    """Validate a kernel input array: one of ``dtypes``, ``ndim`` dimensions, non-empty, C-contiguous.

    The one family every matcher input check builds on (:func:`check_image`,
    :func:`check_disparity`, the cost volumes).

    Parameters
    ----------
    a : object
        The value to check.
    name : str
        Argument name used in the messages.
    dtypes : tuple of numpy scalar types
        Accepted dtypes.
    ndim : int or tuple of int
        Required number of dimensions (one of them).
    layout : str
        Human-readable shape named in the message, e.g. ``"H x W x D"``.
    contiguous : bool
        Require C-contiguity (inputs handed to a kernel as they are).

    Returns
    -------
    ndarray
        ``a`` unchanged.

    Raises
    ------
    TypeError
        Not an array or wrong dtype.
    ValueError
        Wrong number of dimensions, empty, or not C-contiguous.
    """
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(a).__name__}")
    names = [np.dtype(d).name for d in dtypes]
    if a.dtype not in [np.dtype(d) for d in dtypes]:
        allowed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]
        raise TypeError(f"{name} must be {allowed}, got dtype {a.dtype}")
    if a.ndim not in ((ndim,) if isinstance(ndim, int) else ndim):
        raise ValueError(f"{name} must be {layout}, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name} is empty (shape {a.shape})")
    if contiguous and not a.flags.c_contiguous:
        raise ValueError(f"{name} must be C-contiguous (use np.ascontiguousarray)")
    return a


#: Float dtypes a disparity map may arrive in (converted to float32 where accepted).
FLOAT_DTYPES: tuple[type, ...] = (np.float16, np.float32, np.float64, np.longdouble)


_IMAGE_LAYOUT = "H x W or H x W x C with C in (1, 3)"


def check_image(img: object, name: str) -> np.ndarray:
    """Validate one image: C-contiguous uint8, H x W or H x W x C (C = 1 | 3), non-empty.

    Returns the array unchanged. Raises TypeError (not an array / wrong dtype)
    or ValueError (shape, emptiness, contiguity) naming ``name``.
    """
    img = check_array(img, name, (np.uint8,), (2, 3), _IMAGE_LAYOUT)
    if img.ndim == 3 and img.shape[2] not in (1, 3):
        raise ValueError(f"{name} must be {_IMAGE_LAYOUT}, got shape {img.shape}")
    return img


def check_disparity(a: object, name: str, shape: tuple[int, ...] | None = None, *, convert: bool = False) -> np.ndarray:
    """Validate an H x W disparity map: float, non-empty, NaN = invalid, no +-inf.

    Parameters
    ----------
    a : object
        The value to check.
    name : str
        Argument name used in the messages.
    shape : tuple of int or None
        Required (H, W), e.g. the images'.
    convert : bool
        False: a kernel input, C-contiguous float32, returned unchanged.
        True: any float dtype and layout, returned as C-contiguous float32
        (copied only when needed).

    Returns
    -------
    ndarray
        The map (float32).

    Raises
    ------
    TypeError
        Not an array or not float (float32 when ``convert`` is False).
    ValueError
        Not 2-D, empty, not C-contiguous (``convert`` False), wrong shape, or +-inf.
    """
    a = check_array(a, name, FLOAT_DTYPES if convert else (np.float32,), 2, "a 2-D (H x W) map", contiguous=not convert)
    if shape is not None and a.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {a.shape}")
    if np.isinf(a).any():
        raise ValueError(f"{name} contains +-inf; use NaN for 'no value'")
    return np.ascontiguousarray(a, dtype=np.float32) if convert else a


def check_pair(left: object, right: object) -> tuple[np.ndarray, np.ndarray]:
    """Validate a stereo pair: both pass :func:`check_image` and have the same shape."""
    left = check_image(left, "left")
    right = check_image(right, "right")
    if left.shape != right.shape:
        raise ValueError(f"left and right must have the same shape, got {left.shape} and {right.shape}")
    return left, right


def check_hints(hints: object, shape: tuple[int, int]) -> np.ndarray:
    """Validate a sparse-disparity hint map; return it as C-contiguous float32.

    NaN or values <= 0 mean "no hint"; +-inf is rejected (:func:`check_disparity`).
    """
    return check_disparity(hints, "hints", shape, convert=True)


def to_gray(img: np.ndarray) -> np.ndarray:
    """H x W uint8 luminance of a checked image (RGB weights 0.299/0.587/0.114)."""
    if img.ndim == 2:
        return img
    if img.shape[2] == 1:
        return np.ascontiguousarray(img[:, :, 0])
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)


__all__ = [
    "FLOAT_DTYPES",
    "check_array",
    "check_disparity",
    "check_hints",
    "check_image",
    "check_pair",
    "to_gray",
]
