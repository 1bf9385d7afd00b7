"""Reader of the ETH3D two-view stereo set.

Layout: ``<scene>/im0.png``, ``im1.png`` (gray stored as RGB; kept RGB),
``calib.txt`` (Middlebury-style, without ``vmin``/``vmax``), ground truth
``disp0GT.pfm`` or ``disp0.pfm`` (+inf invalid -> NaN) and optionally
``mask0nocc.png`` (255 = non-occluded).
"""

from __future__ import annotations

from pathlib import Path

from vpp_service.datasets.base import DATASETS
from vpp_service.datasets.middlebury import Middlebury2014


@DATASETS.register("eth3d")
class ETH3D(Middlebury2014):
    """ETH3D two-view scenes (``im0.png``, ``im1.png``, ``calib.txt``, ``disp0GT.pfm``).

    Parameters
    ----------
    root : str or Path
        Folder of scene folders (or one scene folder).

    Notes
    -----
    ``max_disparity`` is ``None``: ETH3D's ``ndisp`` is the image width, no useful hint.
    """

    name = "eth3d"
    layout = "<scene>/im0.png, im1.png, calib.txt without vmin, disp0GT.pfm or disp0.pfm [mask0nocc.png]"

    calib_has_vmin = False

    def __init__(self, root: str | Path) -> None:
        super().__init__(root)
        self.max_disparity = None


__all__ = ["ETH3D"]
