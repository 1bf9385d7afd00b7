"""Readers of stereo benchmark folders, all yielding :class:`~vpp_service.frame.StereoFrame`.

>>> from vpp_service.datasets import open_dataset
>>> ds = open_dataset("auto", "../shared/data/middlebury2005_2006_thirdsize")  # doctest: +SKIP
>>> frame = ds[0]  # doctest: +SKIP

Readers (``DATASETS.names()``): ``middlebury2014``, ``middlebury2006``,
``middlebury2003``, ``middlebury2001``, ``eth3d``, ``kitti2012``, ``kitti2015``,
``folder``. ``open_dataset("auto", root)`` tries them in ``AUTO_ORDER``.
"""

from vpp_service.datasets import eth3d as _eth3d  # noqa: F401
from vpp_service.datasets import folder as _folder  # noqa: F401
from vpp_service.datasets import kitti as _kitti  # noqa: F401
from vpp_service.datasets import middlebury as _middlebury  # noqa: F401  (registers readers)
from vpp_service.datasets.base import AUTO_ORDER, DATASETS, Dataset, open_dataset
from vpp_service.datasets.pfm import read_pfm, write_pfm

__all__ = ["AUTO_ORDER", "DATASETS", "Dataset", "open_dataset", "read_pfm", "write_pfm"]
