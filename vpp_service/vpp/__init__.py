"""VPP core library: Virtual Pattern Projection for stereo + sparse depth fusion.

Public API: :class:`VPPConfig`, :func:`project` (-> :class:`VPPResult` with
:class:`VPPStats`), :func:`detect_occlusions`, and the geometry helpers
:func:`depth_to_disparity`, :func:`disparity_to_depth`, :func:`points_to_depth_map`.
See ``docs/algorithm.md``.
"""
from .config import VPPConfig
from .geometry import depth_to_disparity, disparity_to_depth, points_to_depth_map
from .occlusion import detect_occlusions
from .project import VPPResult, VPPStats, project

__all__ = ["VPPConfig", "VPPResult", "VPPStats", "project", "detect_occlusions",
           "depth_to_disparity", "disparity_to_depth", "points_to_depth_map"]
