"""Type stubs of the compiled guided-stereo kernel (``_guided.pyx``).

Unchecked: :func:`vpp_service.matchers.guided.modulate_cost` validates the arguments.
"""

import numpy as np
import numpy.typing as npt

def modulate(
    cost: npt.NDArray[np.uint8] | npt.NDArray[np.uint16] | npt.NDArray[np.float32],
    hints: npt.NDArray[np.float32],
    k: float,
    c: float,
    nthreads: int,
) -> None:
    """In place: scale ``cost`` (H x W x D, C-contiguous) by the Gaussian of each valid hint (H x W)."""
