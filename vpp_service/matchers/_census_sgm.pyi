"""Type stubs of the compiled Census-SGM kernels (``_census_sgm.pyx``).

Unchecked kernels: arrays must be C-contiguous with the dtypes given here and the
shapes the wrappers in :mod:`vpp_service.matchers.census_sgm` allocate. Outputs are
written in place. ``nthreads`` >= 1.
"""

import numpy as np
import numpy.typing as npt

def census5x5(img: npt.NDArray[np.uint8], out: npt.NDArray[np.uint32], nthreads: int) -> None:
    """24-bit 5x5 census of ``img`` (H x W) into ``out`` (H x W)."""

def hamming_volume(
    cl: npt.NDArray[np.uint32],
    cr: npt.NDArray[np.uint32],
    out: npt.NDArray[np.uint16],
    invalid_cost: int,
    nthreads: int,
) -> None:
    """Hamming cost volume ``out`` (H x W x D) of the left and right census images."""

def aggregate(
    C: npt.NDArray[np.uint16],
    g: npt.NDArray[np.uint8],
    S: npt.NDArray[np.uint16],
    paths: int,
    P1: int,
    p2lut: npt.NDArray[np.int16],
    nthreads: int,
) -> None:
    """SGM aggregation of ``C`` over 4 or 8 paths into ``S`` (both H x W x D)."""

def winner_takes_all(
    S: npt.NDArray[np.uint16],
    out: npt.NDArray[np.float32],
    uniqueness: float,
    subpixel: bool,
    nthreads: int,
) -> None:
    """Left disparity ``out`` (H x W, NaN = rejected) from the aggregated volume ``S``."""

def right_disparity(S: npt.NDArray[np.uint16], out: npt.NDArray[np.float32], nthreads: int) -> None:
    """Right-view disparity ``out`` (H x W) read from the left volume ``S``."""

def left_right_check(
    dl: npt.NDArray[np.float32],
    dr: npt.NDArray[np.float32],
    out: npt.NDArray[np.float32],
    tolerance: float,
    nthreads: int,
) -> None:
    """``out`` = ``dl`` where the right view agrees within ``tolerance``, else NaN."""

def median3x3(src: npt.NDArray[np.float32], out: npt.NDArray[np.float32], nthreads: int) -> None:
    """3x3 median over the valid neighbours of each valid pixel of ``src``."""
