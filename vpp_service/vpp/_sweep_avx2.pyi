"""The x86-64-v3 build of the sweep kernel: the same interface as ``_sweep``."""
from ._sweep import *  # noqa: F401,F403
from ._sweep import AVX2 as AVX2, TABLE_SIZE as TABLE_SIZE, ROW_STEP as ROW_STEP
