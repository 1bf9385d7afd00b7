"""Stereo matchers registered by name, hole filling and guided stereo.

>>> from vpp_service.matchers import MATCHERS, build_matcher, fill_holes
>>> MATCHERS.names()
['bm', 'census-sgm', 'onnx', 'psmnet', 'sgbm']

- ``sgbm`` / ``bm``: OpenCV (:mod:`~vpp_service.matchers.opencv`);
- ``census-sgm``: the paper's rSGM recipe in Cython, with guided stereo
  (:mod:`~vpp_service.matchers.census_sgm`, :mod:`~vpp_service.matchers.guided`);
- ``onnx`` / ``psmnet``: stereo networks exported to ONNX, run by OpenVINO or
  ONNX Runtime (:mod:`~vpp_service.matchers.onnx`, engines imported on first use);
  ``psmnet`` is ``onnx`` with the shipped card ``cards/psmnet.toml`` (one matcher per card there);
- :func:`fill_holes`: the evaluation protocol's background interpolation
  (:mod:`~vpp_service.matchers.holes`).

See :mod:`vpp_service.matchers.base` for the conventions all matchers share.
"""

from vpp_service.matchers import census_sgm, onnx, opencv  # noqa: F401  (register census-sgm, onnx, psmnet, sgbm, bm)
from vpp_service.matchers.base import (
    MATCHERS,
    DisparityRangeError,
    Matcher,
    MatcherOptions,
    MatcherRuntime,
    build_matcher,
)
from vpp_service.matchers.guided import modulate_cost
from vpp_service.matchers.holes import fill_holes
from vpp_service.matchers.speckle import remove_speckles

__all__ = [
    "MATCHERS",
    "DisparityRangeError",
    "Matcher",
    "MatcherOptions",
    "MatcherRuntime",
    "build_matcher",
    "fill_holes",
    "modulate_cost",
    "remove_speckles",
]
