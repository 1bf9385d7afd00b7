"""VPP core library: Virtual Pattern Projection for stereo + sparse depth fusion.

Public API: :class:`VPPConfig`, :func:`project` (-> :class:`VPPResult` with
:class:`VPPStats`), :func:`detect_occlusions`, and the geometry helpers
:func:`depth_to_disparity`, :func:`disparity_to_depth`, :func:`points_to_depth_map`.
See ``docs/algorithm.md``.
"""

from vpp_service.vpp.config import VPPConfig
from vpp_service.vpp.geometry import depth_to_disparity, disparity_to_depth, points_to_depth_map
from vpp_service.vpp.occlusion import detect_occlusions
from vpp_service.vpp.project import VPPResult, VPPStats, project

__all__ = [
    "VPPConfig",
    "VPPResult",
    "VPPStats",
    "depth_to_disparity",
    "detect_occlusions",
    "disparity_to_depth",
    "points_to_depth_map",
    "project",
]
