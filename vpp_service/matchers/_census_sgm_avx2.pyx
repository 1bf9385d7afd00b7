# The Census-SGM kernels compiled for x86-64-v3 (setup.py adds -mavx2 -mfma -mbmi2 ... for modules
# named *_avx2): the same source, selected at import by vpp_service.matchers.census_sgm when
# vpp_service.vpp.backend selects the AVX2 build of the VPP kernel.
include "_census_sgm.pyx"
