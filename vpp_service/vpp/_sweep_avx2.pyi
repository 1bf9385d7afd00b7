"""The x86-64-v3 build of the sweep kernel: the same interface as ``_sweep``."""

from vpp_service.vpp._sweep import *
from vpp_service.vpp._sweep import AVX2 as AVX2
from vpp_service.vpp._sweep import ROW_STEP as ROW_STEP
from vpp_service.vpp._sweep import TABLE_SIZE as TABLE_SIZE
