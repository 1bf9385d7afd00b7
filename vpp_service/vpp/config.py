"""Validated, frozen configuration of the Virtual Pattern Projection step.

One :class:`VPPConfig` names a complete VPP variant: the pattern (random or
histogram), the patch (size, uniform or per-pixel, optionally adaptive), the
blending, the sub-pixel splatting and the occlusion strategy.  Every field
declares its constraints (:mod:`vpp_service.settings` markers); a bad value
raises :class:`~vpp_service.settings.OptionError` (a :class:`ValueError`; also
a :class:`TypeError` for a wrong type) naming the field.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Annotated

from vpp_service.settings import Odd, OneOf, Options, Range

PATTERNS = ("random", "histogram")
OCCLUSION_MODES = ("fgd", "no", "bkgd", "off")
ADAPTIVE_MODES = (None, "distance", "bilateral")


@dataclass(frozen=True)
class VPPConfig(Options):
    """Parameters of one VPP variant (defaults: the paper's pattern (vi)).

    Parameters
    ----------
    pattern : {"random", "histogram"}
        How the pattern value is chosen (paper Sec. 3.2): uniform random bytes,
        or the value farthest from every value present in the two search
        windows ("histogram").
    patch : int
        Patch side ``k`` (odd, >= 1); 1 is point-wise.  Default 3.
    uniform_patch : bool
        True: one value for the whole patch (variants iv/v); False (default):
        an independent value per patch pixel (variants vi/vii).
    alpha : float
        Blending weight in [0, 1] (1 replaces the content).  Default 0.4.
    splat : bool
        Sub-pixel splatting in the right view (default True); False rounds
        ``x'`` to the nearest column.
    occlusion : {"fgd", "no", "bkgd", "off"}
        Occlusion strategy; "off" runs no detection at all.  Default "fgd".
    search_width, search_height : int
        Histogram window length ``L`` (>= 1, default 64) and height (odd, default 3).
    occ_window_x, occ_window_y : int
        Occlusion heuristic window ``r_x x r_y`` (odd, default 9 x 7).
    occ_lambda, occ_gamma, occ_t : float
        Occlusion heuristic ``lambda`` (>= 0), ``gamma`` (in [0, 1]) and ``t``.
    adaptive_patch : {None, "distance", "bilateral"}
        Journal extensions: half-size growing with disparity, or a bilateral
        mask inside the patch.
    adaptive_gamma : float
        Exponent ``gamma_d`` (> 0) of the distance-adaptive patch.  Default 0.3.
    adaptive_max_disparity : float or None
        ``d_max`` of the distance-adaptive patch; None = the frame's largest
        valid disparity.
    bilateral_sigma_space, bilateral_sigma_color : float
        Bilateral sigmas (> 0), pixels and grey levels.  Default 2 and 2.
    bilateral_threshold : float
        Paint a patch pixel only where the bilateral weight exceeds this
        value, in (0, 1).  Default 0.001.
    """

    pattern: Annotated[str, OneOf(*PATTERNS)] = "random"
    patch: Annotated[int, Range(1), Odd()] = 3
    uniform_patch: bool = False
    alpha: Annotated[float, Range(0.0, 1.0)] = 0.4
    splat: bool = True
    occlusion: Annotated[str, OneOf(*OCCLUSION_MODES)] = "fgd"
    search_width: Annotated[int, Range(1)] = 64
    search_height: Annotated[int, Range(1), Odd()] = 3
    occ_window_x: Annotated[int, Range(1), Odd()] = 9
    occ_window_y: Annotated[int, Range(1), Odd()] = 7
    occ_lambda: Annotated[float, Range(0.0)] = 2.0
    occ_gamma: Annotated[float, Range(0.0, 1.0)] = 0.4375
    occ_t: Annotated[float, Range(0.0)] = 1.0
    adaptive_patch: Annotated[str | None, OneOf(*ADAPTIVE_MODES)] = None
    adaptive_gamma: Annotated[float, Range(0.0, lo_open=True)] = 0.3
    adaptive_max_disparity: Annotated[float | None, Range(0.0, lo_open=True)] = None
    bilateral_sigma_space: Annotated[float, Range(0.0, lo_open=True)] = 2.0
    bilateral_sigma_color: Annotated[float, Range(0.0, lo_open=True)] = 2.0
    bilateral_threshold: Annotated[float, Range(0.0, 1.0, lo_open=True, hi_open=True)] = 0.001

    def to_dict(self) -> dict[str, str | int | float | bool | None]:
        """Plain-dict form of the config, JSON and msgpack friendly.

        :func:`vpp_service.settings.from_mapping` (``from_mapping(VPPConfig, d)``)
        builds a config back from such a mapping.
        """
        return asdict(self)
