"""Your own sparse depth for a frame of the ``folder`` layout: one file per frame in ``sparse/``.

The file is named after the left image (``left/000.png`` -> ``sparse/000.<ext>``)
and holds the sparse input of that frame, in one of these forms:

``.png``
    An 8- or 16-bit single-channel disparity image of the frame's size;
    disparity = value / ``disp_scale`` (the folder reader's option, default 256,
    KITTI style), 0 = no point.
``.npy``
    A 2-D float array of the frame's size: disparity in pixels; NaN or 0 = no
    point. Infinite or negative values are an error.
``.csv`` / ``.txt``
    Points, one per line, three numbers separated by commas or blanks, after a
    header line that names the columns (lines starting with ``#`` are comments):

    - ``u v d`` (or ``u,v,disparity``): pixel column, pixel row (0-based, in the
      left image, rounded to the nearest pixel) and disparity in pixels (> 0);
      a point outside the image is an error.
    - ``x y z``: metres in the rectified left camera frame (x right, y down,
      z forward), e.g. a LiDAR scan already transformed into it. Needs the
      folder's ``calib.json``: a point projects to ``u = f x / z + cx``,
      ``v = f y / z + cy`` with disparity ``f * baseline / z - doffs``; points
      behind the camera or outside the image are dropped (a scanner sees more
      than the camera), and where several land on one pixel the nearest wins.
      Such frames are marked LiDAR-like (``meta["lidar_like"]``): the fusion
      step's ``auto`` depth filter removes points that see through foreground
      edges.

Every number must be finite: a NaN in a points file, a map of another size, a
point outside the image, an unreadable file, a frame without its file, all make
:func:`read_sparse` raise ``ValueError`` / ``FileNotFoundError`` naming the
file, so a replay rejects (and counts) that frame only.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import cv2
import numpy as np

from vpp_service.frame import Calibration

#: File types a ``sparse/`` folder may hold.
SPARSE_EXT = (".png", ".npy", ".csv", ".txt")

#: Header of a points file -> its kind.
_HEADERS: dict[tuple[str, ...], str] = {("u", "v", "d"): "uvd", ("u", "v", "disparity"): "uvd", ("x", "y", "z"): "xyz"}

_SEP = re.compile(r"[,\s]+")


def read_sparse(
    path: Path, shape: tuple[int, int], calib: Calibration | None, disp_scale: float = 256.0
) -> tuple[np.ndarray, bool]:
    """Read one frame's sparse input.

    Parameters
    ----------
    path : Path
        ``sparse/<stem>.png|.npy|.csv|.txt``.
    shape : (H, W)
        The frame's image size.
    calib : Calibration or None
        The folder's calibration (needed by ``x y z`` points).
    disp_scale : float
        Divisor of a PNG's integer values.

    Returns
    -------
    sparse : ndarray
        H x W float32 disparity, NaN = no point.
    lidar_like : bool
        True for ``x y z`` points (a scanner's view, see the module docstring).

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is unreadable, of another size, holds a non-finite or negative value,
        a point outside the image, or ``x y z`` points without a calibration.
    """
    if not path.is_file():
        raise FileNotFoundError(f"sparse: {path} not found")
    ext = path.suffix.lower()
    if ext == ".png":
        return _read_png(path, shape, disp_scale), False
    if ext == ".npy":
        return _read_npy(path, shape), False
    if ext in (".csv", ".txt"):
        return _read_points(path, shape, calib)
    raise ValueError(f"sparse: {path.name}: unknown type {ext!r}; use one of {', '.join(SPARSE_EXT)}")


def _check_shape(path: Path, got: tuple[int, ...], shape: tuple[int, int]) -> None:
    if tuple(got) != tuple(shape):
        raise ValueError(
            f"sparse: {path.name} is {'x'.join(map(str, got))} (rows x columns), the images are {shape[0]}x{shape[1]}"
        )


def _read_png(path: Path, shape: tuple[int, int], disp_scale: float) -> np.ndarray:
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise ValueError(f"sparse: cannot decode {path}")
    if raw.ndim != 2 or raw.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"sparse: {path.name} must be a single-channel 8- or 16-bit PNG, got {raw.dtype} {raw.shape}")
    _check_shape(path, raw.shape, shape)
    disp = raw.astype(np.float32) / np.float32(disp_scale)
    disp[raw == 0] = np.nan
    return disp


def _read_npy(path: Path, shape: tuple[int, int]) -> np.ndarray:
    try:
        raw = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"sparse: cannot read {path}: {exc}") from None
    if raw.ndim != 2 or not np.issubdtype(raw.dtype, np.number):
        raise ValueError(f"sparse: {path.name} must hold a 2-D numeric array, got {raw.dtype} {raw.shape}")
    _check_shape(path, raw.shape, shape)
    disp = raw.astype(np.float32)
    bad = np.isinf(disp) | (disp < 0)
    if bad.any():
        y, x = np.argwhere(bad)[0]
        raise ValueError(
            f"sparse: {path.name} holds {np.count_nonzero(bad)} infinite or negative values "
            f"(first at row {y}, column {x}: {disp[y, x]}); NaN or 0 = no point"
        )
    disp[disp == 0] = np.nan
    return disp


def _read_points(path: Path, shape: tuple[int, int], calib: Calibration | None) -> tuple[np.ndarray, bool]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"sparse: cannot read {path}: {exc}") from None
    body = [(i + 1, s) for i, line in enumerate(lines) if (s := line.strip()) and not s.startswith("#")]
    if not body:
        raise ValueError(f"sparse: {path.name} is empty (expected a header 'u v d' or 'x y z', then points)")
    header = tuple(t.lower() for t in _SEP.split(body[0][1]) if t)
    kind = _HEADERS.get(header)
    if kind is None:
        raise ValueError(
            f"sparse: {path.name} line {body[0][0]}: header {body[0][1]!r} is not 'u v d' (or 'u,v,disparity') "
            "nor 'x y z'"
        )
    rows = body[1:]
    pts = np.empty((0, 3))
    if rows:
        try:
            pts = np.loadtxt(io.StringIO("\n".join(_SEP.sub(" ", s) for _, s in rows)), ndmin=2, dtype=np.float64)
        except ValueError as exc:
            raise ValueError(f"sparse: {path.name}: {exc}") from None
        if pts.shape[1] != 3:
            raise ValueError(f"sparse: {path.name}: expected 3 numbers per line, got {pts.shape[1]}")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        line = rows[int(np.argmax(bad))][0]
        raise ValueError(f"sparse: {path.name} line {line}: a non-finite number ({np.count_nonzero(bad)} such lines)")
    h, w = shape
    out = np.full((h, w), -np.inf, np.float64)
    if kind == "uvd":
        u, v, d = np.rint(pts[:, 0]).astype(np.int64), np.rint(pts[:, 1]).astype(np.int64), pts[:, 2]
        outside = (u < 0) | (u >= w) | (v < 0) | (v >= h)
        if outside.any():
            line = rows[int(np.argmax(outside))][0]
            raise ValueError(
                f"sparse: {path.name} line {line}: a point outside the {w}x{h} image "
                f"({np.count_nonzero(outside)} such points)"
            )
        if (d <= 0).any():
            line = rows[int(np.argmax(d <= 0))][0]
            raise ValueError(f"sparse: {path.name} line {line}: disparity must be > 0")
    else:
        if calib is None:
            raise ValueError(f"sparse: {path.name}: 'x y z' points need the folder's calib.json (f, baseline)")
        cx = calib.cx if calib.cx is not None else (w - 1) / 2.0
        cy = calib.cy if calib.cy is not None else (h - 1) / 2.0
        x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
        front = z > 0
        x, y, z = x[front], y[front], z[front]
        u, v = np.rint(calib.f * x / z + cx).astype(np.int64), np.rint(calib.f * y / z + cy).astype(np.int64)
        d = calib.f * calib.baseline / z - calib.doffs
        keep = (u >= 0) & (u < w) & (v >= 0) & (v < h) & (d > 0)
        u, v, d = u[keep], v[keep], d[keep]
    np.maximum.at(out, (v, u), d)  # several points on one pixel: the nearest (largest disparity) wins
    sparse = np.where(np.isfinite(out), out, np.nan).astype(np.float32)
    return sparse, kind == "xyz"


__all__ = ["SPARSE_EXT", "read_sparse"]
