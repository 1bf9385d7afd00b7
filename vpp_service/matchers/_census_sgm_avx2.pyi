"""The x86-64-v3 build of the Census-SGM kernels: the same interface as ``_census_sgm``."""

from vpp_service.matchers._census_sgm import AVX2 as AVX2
from vpp_service.matchers._census_sgm import aggregate as aggregate
from vpp_service.matchers._census_sgm import byte_path_costs as byte_path_costs
from vpp_service.matchers._census_sgm import census5x5 as census5x5
from vpp_service.matchers._census_sgm import cost_stage as cost_stage
from vpp_service.matchers._census_sgm import cost_work_bytes as cost_work_bytes
from vpp_service.matchers._census_sgm import hamming_volume as hamming_volume
from vpp_service.matchers._census_sgm import keyed_wta as keyed_wta
from vpp_service.matchers._census_sgm import left_right_check as left_right_check
from vpp_service.matchers._census_sgm import median3x3 as median3x3
from vpp_service.matchers._census_sgm import narrow_sums as narrow_sums
from vpp_service.matchers._census_sgm import right_disparity as right_disparity
from vpp_service.matchers._census_sgm import scratch_bytes as scratch_bytes
from vpp_service.matchers._census_sgm import sgm_stage as sgm_stage
from vpp_service.matchers._census_sgm import winner_takes_all as winner_takes_all
