"""Type stubs of the compiled sweep kernel (``_sweep.pyx``; ``_sweep_avx2`` is the same module)."""

import enum

import numpy as np
import numpy.typing as npt

from vpp_service.vpp.params import KernelParams

class Pattern(enum.IntEnum):
    RANDOM = 0
    HISTOGRAM = 1

class Occlusion(enum.IntEnum):
    OCC_OFF = 0
    OCC_NO = 1
    OCC_BKGD = 2
    OCC_FGD = 3

class PatchMask(enum.IntEnum):
    MASK_FULL = 0
    MASK_DISTANCE = 1
    MASK_BILATERAL = 2

AVX2: bool
TABLE_SIZE: int
ROW_STEP: int

def cpu_supports_avx2() -> bool: ...
def table_padding(C: int, hmax: int) -> int: ...
def fill_pattern_table(seed: int, out: npt.NDArray[np.uint8], C: int) -> None: ...
def hist_pick_bits(occupancy: npt.NDArray[np.uint64]) -> int: ...
def release_scratch() -> int: ...
def paint(
    disp: npt.NDArray[np.float32],
    occ: npt.NDArray[np.uint8],
    left: npt.NDArray[np.uint8],
    right: npt.NDArray[np.uint8],
    out_left: npt.NDArray[np.uint8],
    out_right: npt.NDArray[np.uint8],
    params: KernelParams,
    pattern: npt.NDArray[np.uint8] | None,
    nthreads: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]: ...
def occlusions(
    disp: npt.NDArray[np.float32],
    occ: npt.NDArray[np.uint8],
    params: KernelParams,
    nthreads: int,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]: ...
