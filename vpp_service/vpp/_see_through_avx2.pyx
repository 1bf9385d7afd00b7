# The see-through filter kernel compiled for x86-64-v3 (setup.py adds -mavx2 -mfma -mbmi2 ... for modules
# named *_avx2): the same source, selected at import by vpp_service.vpp.see_through when
# vpp_service.vpp.backend selects the AVX2 build of the VPP kernel.
include "_see_through.pyx"
