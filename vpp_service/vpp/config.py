"""Validated, frozen configuration of the Virtual Pattern Projection step.

One :class:`VPPConfig` names a complete VPP variant: the pattern (random or
histogram), the patch (size, uniform or per-pixel, optionally adaptive), the
blending, the sub-pixel splatting and the occlusion strategy.  Every field is
checked in ``__post_init__``; a bad value raises :class:`ValueError` (or
:class:`TypeError` for a wrong type) naming the field.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

PATTERNS = ("random", "histogram")
OCCLUSION_MODES = ("fgd", "no", "bkgd", "off")
ADAPTIVE_MODES = (None, "distance", "bilateral")


def _check_bool(name: str, v: object) -> None:
    if not isinstance(v, bool):
        raise TypeError(f"VPPConfig.{name} must be a bool, got {type(v).__name__}")


def _check_int(name: str, v: object, lo: int, *, odd: bool = False) -> None:
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError(f"VPPConfig.{name} must be an int, got {type(v).__name__}")
    if v < lo:
        raise ValueError(f"VPPConfig.{name} must be >= {lo}, got {v}")
    if odd and v % 2 == 0:
        raise ValueError(f"VPPConfig.{name} must be odd, got {v}")


def _check_float(
    name: str,
    v: object,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"VPPConfig.{name} must be a number, got {type(v).__name__}")
    if not math.isfinite(v):
        raise ValueError(f"VPPConfig.{name} must be finite, got {v}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"VPPConfig.{name} must be {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"VPPConfig.{name} must be {'<' if hi_open else '<='} {hi}, got {v}")


@dataclass(frozen=True)
class VPPConfig:
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

    pattern: str = "random"
    patch: int = 3
    uniform_patch: bool = False
    alpha: float = 0.4
    splat: bool = True
    occlusion: str = "fgd"
    search_width: int = 64
    search_height: int = 3
    occ_window_x: int = 9
    occ_window_y: int = 7
    occ_lambda: float = 2.0
    occ_gamma: float = 0.4375
    occ_t: float = 1.0
    adaptive_patch: str | None = None
    adaptive_gamma: float = 0.3
    adaptive_max_disparity: float | None = None
    bilateral_sigma_space: float = 2.0
    bilateral_sigma_color: float = 2.0
    bilateral_threshold: float = 0.001

    def __post_init__(self) -> None:
        if self.pattern not in PATTERNS:
            raise ValueError(f"VPPConfig.pattern must be one of {PATTERNS}, got {self.pattern!r}")
        if self.occlusion not in OCCLUSION_MODES:
            raise ValueError(f"VPPConfig.occlusion must be one of {OCCLUSION_MODES}, got {self.occlusion!r}")
        if self.adaptive_patch not in ADAPTIVE_MODES:
            raise ValueError(f"VPPConfig.adaptive_patch must be one of {ADAPTIVE_MODES}, got {self.adaptive_patch!r}")
        _check_int("patch", self.patch, 1, odd=True)
        _check_bool("uniform_patch", self.uniform_patch)
        _check_bool("splat", self.splat)
        _check_float("alpha", self.alpha, 0.0, 1.0)
        _check_int("search_width", self.search_width, 1)
        _check_int("search_height", self.search_height, 1, odd=True)
        _check_int("occ_window_x", self.occ_window_x, 1, odd=True)
        _check_int("occ_window_y", self.occ_window_y, 1, odd=True)
        _check_float("occ_lambda", self.occ_lambda, 0.0)
        _check_float("occ_gamma", self.occ_gamma, 0.0, 1.0)
        _check_float("occ_t", self.occ_t, 0.0)
        _check_float("adaptive_gamma", self.adaptive_gamma, 0.0, lo_open=True)
        if self.adaptive_max_disparity is not None:
            _check_float("adaptive_max_disparity", self.adaptive_max_disparity, 0.0, lo_open=True)
        _check_float("bilateral_sigma_space", self.bilateral_sigma_space, 0.0, lo_open=True)
        _check_float("bilateral_sigma_color", self.bilateral_sigma_color, 0.0, lo_open=True)
        _check_float("bilateral_threshold", self.bilateral_threshold, 0.0, 1.0, lo_open=True, hi_open=True)

    def to_dict(self) -> dict[str, str | int | float | bool | None]:
        """Plain-dict form of the config, JSON and msgpack friendly.

        :func:`vpp_service.settings.from_mapping` (``from_mapping(VPPConfig, d)``)
        builds a config back from such a mapping.
        """
        return asdict(self)
