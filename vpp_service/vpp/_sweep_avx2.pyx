# distutils: language = c++
# The sweep kernel compiled for x86-64-v3 (setup.py adds -mavx2 -mfma -mbmi2 ...
# for modules named *_avx2): the same source, selected at import by
# vpp_service.vpp.backend when the CPU supports it.
include "_sweep.pyx"
