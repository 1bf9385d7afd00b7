"""Type stubs of the compiled see-through filter kernel (``_see_through.pyx``).

Unchecked: :func:`vpp_service.vpp.see_through.filter_see_through` validates the arguments.
"""

import numpy as np
import numpy.typing as npt

def see_through_rows(
    src: npt.NDArray[np.float32], dst: npt.NDArray[np.float32], rx: int, ry: int, margin: float, min_gap: float
) -> int:
    """Write ``src``'s points into ``dst`` (NaN elsewhere) less those with nearer values on opposite sides."""
