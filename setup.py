"""Build script: compiles every ``vpp_service/**/*.pyx`` as an OpenMP extension.

New kernels need no edit here: drop a ``.pyx`` next to its Python wrapper.
Set ``VPP_DEBUG_BOUNDS=1`` at build time to compile with bounds checks and
wrap-around on (a debug build used to fuzz the wrappers against out-of-bounds
access); the default build turns them off for speed.

A kernel already built in place (``pip install -e .`` leaves the compiled modules
next to their sources) and newer than its ``.pyx`` and headers is reused instead of
being cythonized and compiled again, so the README's second command
(``pip install -e ".[test]"``) does not rebuild what its first command built.
``build_ext --force`` (or a debug build) compiles everything; so does deleting the
``.so`` files.
"""

import os
import platform
import shutil
import sys
import sysconfig
from pathlib import Path

import numpy as np
from Cython.Build import cythonize
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

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


def sources_text(pyx: Path) -> str:
    """The text of ``pyx`` and, for an ``_avx2`` module, of the portable source it includes (headers named there)."""
    text = pyx.read_text(encoding="utf-8")
    base = pyx.with_name(pyx.name.replace("_avx2", ""))
    return text + (base.read_text(encoding="utf-8") if base != pyx else "")


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
            depends=[str(h.relative_to(ROOT)) for h in pyx.parent.glob("*.h") if h.name in sources_text(pyx)]
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

EXT_SUFFIX = sysconfig.get_config_var("EXT_SUFFIX")
rebuild = debug_bounds or bool({"--force", "-f"} & set(sys.argv))


def built_in_place(ext: Extension) -> Path | None:
    """``ext``'s compiled module next to its sources when newer than the project's sources of it (.pyx, .h).

    Generated C and Cython's own includes are not compared: a fresh isolated build
    environment gives those new times although nothing the module is built from changed.
    """
    module = ROOT / (ext.name.replace(".", "/") + EXT_SUFFIX)
    ours = [ROOT / p for p in [*ext.sources, *ext.depends]]
    if rebuild or not module.is_file():
        return None
    newest = max(p.stat().st_mtime for p in ours)
    return module if newest <= module.stat().st_mtime else None


#: Modules whose in-place build is reused (neither cythonized nor compiled again).
REUSED = {ext.name: built for ext in extensions if (built := built_in_place(ext)) is not None}


class ReusingBuildExt(build_ext):
    """``build_ext`` that copies an up-to-date in-place build of a kernel instead of compiling it again."""

    def build_extension(self, ext: Extension) -> None:
        """Copy ``ext``'s in-place module when :data:`REUSED` lists it; else compile it."""
        built = REUSED.get(ext.name)
        if built is None:
            super().build_extension(ext)
            return
        target = Path(self.get_ext_fullpath(ext.name)).resolve()
        print(f"reusing {built.relative_to(ROOT)} (newer than its sources)")
        if target != built.resolve():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(built, target)


fresh = [ext for ext in extensions if ext.name not in REUSED]
setup(
    ext_modules=[ext for ext in extensions if ext.name in REUSED]
    + (cythonize(fresh, compiler_directives=directives, nthreads=2) if fresh else []),
    cmdclass={"build_ext": ReusingBuildExt},
)
