"""Type stubs of the compiled Census-SGM kernels (``_census_sgm.pyx``; ``_census_sgm_avx2`` is the same module).

Unchecked kernels: arrays must be C-contiguous with the dtypes given here and the
shapes the wrappers in :mod:`vpp_service.matchers.census_sgm` allocate. Outputs are
written in place. ``nthreads`` >= 1.
"""

import numpy as np
import numpy.typing as npt

from vpp_service.matchers.census_sgm import SGMWorkspace, StageParams

#: True in the build compiled for x86-64-v3.
AVX2: bool

def scratch_bytes(W: int, D: int) -> int:
    """Bytes of SGM scratch per pass thread for width ``W`` and ``D`` disparities."""

def narrow_sums(paths: int, p2lut: npt.NDArray[np.int16], volume: bool) -> bool:
    """Whether the SGM keeps its per-pass partial sums as uint8 (else uint16)."""

def byte_path_costs(paths: int, p2lut: npt.NDArray[np.int16], volume: bool, D: int) -> bool:
    """Whether the SGM passes keep their path costs as uint8 too (AVX2 build, 8 paths, D % 16 == 0)."""

def keyed_wta(paths: int, p2lut: npt.NDArray[np.int16], volume: bool, D: int) -> bool:
    """Whether the SGM stage's winner-takes-all runs on 16-bit keys (AVX2 build, narrow sums, D <= 128)."""

def cost_work_bytes(W: int, nthreads: int) -> int:
    """Bytes of census / Hamming scratch for ``nthreads`` threads at width ``W``."""

def cost_stage(
    ws: SGMWorkspace,
    gl: npt.NDArray[np.uint8],
    gr: npt.NDArray[np.uint8],
    cost: npt.NDArray[np.uint16] | None,
    invalid_cost: int,
    nthreads: int,
) -> None:
    """Census of both gray images into ``ws.cl``, ``ws.cr`` and (unless None) their Hamming volume ``cost``."""

def sgm_stage(
    params: StageParams,
    p2lut: npt.NDArray[np.int16],
    ws: SGMWorkspace,
    cost: npt.NDArray[np.uint16] | None,
    gl: npt.NDArray[np.uint8],
    gr: npt.NDArray[np.uint8] | None,
    out: npt.NDArray[np.float32],
    nthreads: int,
    conf: npt.NDArray[np.float32] | None = None,
) -> None:
    """(Census of ``gl``, ``gr``,) SGM of ``cost`` (None: of ``ws.cl``, ``ws.cr``), WTAs, checks, median: ``out``.

    With ``conf`` (H x W float32) also each pixel's confidence in [0, 1].
    """

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
