"""Type stub of the compiled speckle filter kernel (see ``_speckle.pyx``)."""

import numpy as np
import numpy.typing as npt

def speckle_filter(
    src: npt.NDArray[np.float32],
    dst: npt.NDArray[np.float32],
    scratch: npt.NDArray[np.int32],
    max_size: int,
    max_diff16: int,
    nthreads: int,
) -> bool: ...
