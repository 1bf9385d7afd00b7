"""Point clouds as binary little-endian PLY files (the files sink's ``<stem>_points.ply``).

The layout every PLY reader (MeshLab, CloudCompare, Open3D, PCL's ``pcl_ply2pcd``) opens::

    ply
    format binary_little_endian 1.0
    comment <free text, one line each>
    element vertex <n>
    property float x
    property float y
    property float z
    property uchar red
    property uchar green
    property uchar blue
    end_header
    <n records of 15 bytes: x y z float32, red green blue uint8>
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: One vertex record: x y z float32 and an RGB colour, packed (15 bytes).
VERTEX_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])


def encode_ply(xyz: np.ndarray, rgb: np.ndarray, comments: Sequence[str] = ()) -> bytes:
    """A binary little-endian PLY file of ``n`` coloured points.

    Parameters
    ----------
    xyz : ndarray
        N x 3 coordinates (written as float32).
    rgb : ndarray
        N x 3 uint8 colours.
    comments : sequence of str
        ``comment`` lines of the header (single lines, ASCII).

    Returns
    -------
    bytes
        The file contents.

    Raises
    ------
    ValueError
        Shapes that are not N x 3 or disagree, colours that are not uint8, or a comment
        with a line break or non-ASCII text.
    """
    if xyz.ndim != 2 or xyz.shape[1] != 3 or rgb.shape != xyz.shape:
        raise ValueError(f"xyz and rgb must both be N x 3, got {xyz.shape} and {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"rgb must be uint8, got {rgb.dtype}")
    for c in comments:
        if "\n" in c or "\r" in c or not c.isascii():
            raise ValueError(f"a PLY comment must be one ASCII line, got {c!r}")
    n = len(xyz)
    header = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments)]
    header += [f"element vertex {n}"]
    header += [f"property float {a}" for a in "xyz"] + [f"property uchar {c}" for c in ("red", "green", "blue")]
    header += ["end_header"]
    body = np.empty(n, VERTEX_DTYPE)
    body["x"], body["y"], body["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    body["red"], body["green"], body["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    return ("\n".join(header) + "\n").encode("ascii") + body.tobytes()


__all__ = ["VERTEX_DTYPE", "encode_ply"]
