"""The x86-64-v3 build of the sweep kernel: the same interface as ``_sweep``."""

from vpp_service.vpp._sweep import AVX2 as AVX2
from vpp_service.vpp._sweep import ROW_STEP as ROW_STEP
from vpp_service.vpp._sweep import TABLE_SIZE as TABLE_SIZE
from vpp_service.vpp._sweep import Occlusion as Occlusion
from vpp_service.vpp._sweep import PatchMask as PatchMask
from vpp_service.vpp._sweep import Pattern as Pattern
from vpp_service.vpp._sweep import cpu_supports_avx2 as cpu_supports_avx2
from vpp_service.vpp._sweep import fill_pattern_table as fill_pattern_table
from vpp_service.vpp._sweep import hist_pick_bits as hist_pick_bits
from vpp_service.vpp._sweep import occlusions as occlusions
from vpp_service.vpp._sweep import paint as paint
from vpp_service.vpp._sweep import release_scratch as release_scratch
from vpp_service.vpp._sweep import table_padding as table_padding
