"""Build script: compiles every ``vpp_service/**/*.pyx`` as an OpenMP extension.

New kernels need no edit here: drop a ``.pyx`` next to its Python wrapper.
Set ``VPP_DEBUG_BOUNDS=1`` at build time to compile with bounds checks and
wrap-around on (a debug build used to fuzz the wrappers against out-of-bounds
access); the default build turns them off for speed.
"""

import os
import platform
import sys
from pathlib import Path

import numpy as np
from Cython.Build import cythonize
from setuptools import Extension, setup

ROOT = Path(__file__).parent
debug_bounds = os.environ.get("VPP_DEBUG_BOUNDS", "0") == "1"

if sys.platform == "win32":
    compile_args, link_args = ["/O2", "/openmp"], []
elif sys.platform == "darwin":
    compile_args, link_args = ["-O3"], []  # Apple clang ships no OpenMP by default
else:
    compile_args, link_args = ["-O3", "-fopenmp"], ["-fopenmp"]

# Modules named *_avx2 are a second build of a kernel for x86-64-v3 CPUs (AVX2,
# FMA, BMI2, ...), chosen at run time by the Python side when the CPU has them.
x86 = platform.machine().lower() in ("x86_64", "amd64") and sys.platform != "win32"
# No fused multiply-add contraction: both builds round every operation as the
# portable one (and the reference) does.
avx2_args = ["-mavx2", "-mfma", "-mbmi", "-mbmi2", "-mlzcnt", "-mpopcnt", "-mf16c", "-mmovbe", "-ffp-contract=off"]

extensions = []
for pyx in sorted((ROOT / "vpp_service").rglob("*.pyx")):
    module = ".".join(pyx.relative_to(ROOT).with_suffix("").parts)
    avx2 = module.endswith("_avx2")
    if avx2 and not x86:
        continue
    extensions.append(
        Extension(
            module,
            [str(pyx.relative_to(ROOT))],
            depends=[str(h.relative_to(ROOT)) for h in pyx.parent.glob("*.h")]
            + ([str(pyx.with_name(pyx.name.replace("_avx2", "")).relative_to(ROOT))] if avx2 else []),
            include_dirs=[np.get_include()],
            define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
            extra_compile_args=compile_args + (avx2_args if avx2 else []),
            extra_link_args=link_args,
        )
    )

# Safety/speed directives are set here, for every kernel, and nowhere else (a
# directive in a .pyx header or decorator would override the debug build).
directives = {
    "language_level": "3",
    "embedsignature": True,
    "boundscheck": debug_bounds,
    "wraparound": debug_bounds,
    "initializedcheck": debug_bounds,
    "cdivision": True,
}

setup(ext_modules=cythonize(extensions, compiler_directives=directives, nthreads=2))
