"""Guided stereo (Poggi et al., CVPR 2019): modulate a cost volume with sparse hints.

For a cost that is better when lower, at every pixel with a valid hint ``d*``

    cost(x, y, d) <- cost(x, y, d) * k * (1 - exp(-(d - d*)^2 / (2 c^2)))

(the formula of the VPP paper's evaluation, implemented exactly: the cost at
``d = d*`` becomes 0 and far disparities are scaled by ``k``). Pixels without
a hint keep their cost. Only hinted pixels are touched (Cython kernel).

dtype policy: a float32 volume is modulated in float32 (the factor is computed
in double); an integer volume (uint8 / uint16, e.g. census-SGM's Hamming
costs) is rounded to nearest (half up) and saturated at the dtype maximum,
so it can feed the integer SGM aggregation directly. Census costs are <= 24,
so with ``k = 10`` the modulated values (<= 240) lose at most 0.5 per entry.
"""

from __future__ import annotations

import numpy as np

from vpp_service.matchers._guided import modulate
from vpp_service.matchers.inputs import check_array, check_hints
from vpp_service.threads import resolve_threads

_DTYPES = (np.uint8, np.uint16, np.float32)


def modulate_cost(
    cost: np.ndarray,
    hints: np.ndarray,
    k: float = 10.0,
    c: float = 1.0,
    *,
    inplace: bool = False,
    threads: int | None = None,
) -> np.ndarray:
    """Apply the guided-stereo Gaussian modulation to a cost volume.

    Parameters
    ----------
    cost : ndarray
        C-contiguous H x W x D cost volume (lower = better), uint8, uint16 or float32.
    hints : ndarray
        H x W float sparse disparity; NaN or <= 0 = no hint, inf rejected.
    k : float
        Modulation height (> 0, finite). Default 10.
    c : float
        Gaussian width in disparities (> 0, finite). Default 1.
    inplace : bool
        Modify ``cost`` and return it instead of a modulated copy.
    threads : int or None
        OpenMP threads (None = :func:`~vpp_service.threads.default_threads`).

    Returns
    -------
    ndarray
        The modulated volume, same shape and dtype as ``cost``.

    Raises
    ------
    TypeError
        ``cost`` not an array of a supported dtype, ``hints`` not float.
    ValueError
        Bad shapes, non-contiguous ``cost``, empty volume, NaN/inf in a float
        ``cost``, or ``k``/``c`` not finite and > 0.
    """
    cost = check_array(cost, "cost", _DTYPES, 3, "H x W x D")
    if cost.dtype == np.float32 and not np.isfinite(cost).all():
        raise ValueError("cost contains NaN or inf")
    for name, v in (("k", k), ("c", c)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
    h = check_hints(hints, cost.shape[:2])
    out = cost if inplace else cost.copy()
    modulate(out, h, float(k), float(c), resolve_threads(threads))
    return out


__all__ = ["modulate_cost"]
