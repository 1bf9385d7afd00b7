"""Type stubs of the compiled point scatterer (``_points.pyx``).

Unchecked: :func:`vpp_service.transport.wire.points_to_maps` validates the arguments.
"""

from typing import Final

import numpy as np
import numpy.typing as npt

#: Bits of the problem mask returned by :func:`scatter_points` (several may be set).
BAD_UV: Final[int]
OUTSIDE: Final[int]
BAD_VALUE: Final[int]

def scatter_points(
    uv: npt.NDArray[np.float32],
    vals: npt.NDArray[np.float32],
    keep_min: bool,
    out: npt.NDArray[np.float32],
    out_d: npt.NDArray[np.float32],
    fb: float,
    doffs: float,
) -> int:
    """Validate ``n`` points, scatter them into ``out`` and/or ``out_d`` (one may be 0 x 0); return the problem mask."""
