"""Type stubs of the compiled hole-filling kernel (``_holes.pyx``).

Unchecked: :func:`vpp_service.matchers.holes.fill_holes` and
:func:`vpp_service.matchers.holes.fill_short_gaps` validate the arguments.
"""

import numpy as np
import numpy.typing as npt

def fill_rows(src: npt.NDArray[np.float32], dst: npt.NDArray[np.float32], empty: float, nthreads: int) -> None:
    """Write ``src`` (H x W) into ``dst`` with each NaN run set to the smaller of its valid row neighbours."""

def fill_gap_rows(
    src: npt.NDArray[np.float32], dst: npt.NDArray[np.float32], max_gap: int, max_step: float, nthreads: int
) -> None:
    """Copy ``src`` into ``dst`` with interior NaN runs of <= ``max_gap`` pixels filled (linear or the smaller end)."""
