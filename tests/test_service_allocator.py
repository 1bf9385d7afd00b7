"""vpp_service.service.allocator: freed frame buffers are reused (no fresh page faults)."""

from __future__ import annotations

import json
import platform
import subprocess
import sys

import pytest

from vpp_service.service.allocator import reuse_freed_memory

# Allocate, touch and free three frame-sized arrays (several frames "in flight",
# as in the service), then do it again and count the page faults of the second
# round.  Run in a child process: mallopt changes the whole process.
_PROBE = r"""
import json, resource, sys
import numpy as np
if sys.argv[1] == "1":
    from vpp_service.service.allocator import reuse_freed_memory
    assert reuse_freed_memory()
def round_():
    a = [np.empty(6 << 20, np.uint8) for _ in range(3)]
    for x in a:
        x.fill(1)
    del a
round_()
f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
round_()
print(json.dumps(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0))
"""


def faults(reuse: bool) -> int:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, "1" if reuse else "0"], capture_output=True, text=True, timeout=60, check=True
    )
    return json.loads(out.stdout)


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="mallopt is glibc-only")
def test_second_round_reuses_pages():
    pages = 3 * (6 << 20) // 4096
    assert faults(False) > pages // 4  # default: freed arrays go back to the kernel, fault again
    assert faults(True) < pages // 50  # reuse: the freed frames are still mapped


@pytest.mark.parametrize("bad", [0, 2048, True, 1.5, "64"])
def test_bad_threshold(bad):
    with pytest.raises(ValueError, match="mmap_threshold_mb"):
        reuse_freed_memory(bad)


# Under reuse_freed_memory a freed spike stays resident; trim_freed_memory hands it back.
_TRIM_PROBE = r"""
import json, sys
import numpy as np
from vpp_service.service.allocator import reuse_freed_memory, trim_freed_memory
def rss_mb():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 2**20
assert reuse_freed_memory()
base = rss_mb()
spike = [np.ones(8 << 20, np.uint8) for _ in range(20)]  # 160 MiB in heap-served blocks
del spike
kept = rss_mb() - base
ok = trim_freed_memory() if sys.argv[1] == "1" else True
print(json.dumps([ok, kept, rss_mb() - base]))
"""


@pytest.mark.skipif(
    platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc-only"
)
def test_trim_returns_a_freed_spike_to_the_kernel():
    out = subprocess.run(
        [sys.executable, "-c", _TRIM_PROBE, "1"], capture_output=True, text=True, timeout=60, check=True
    )
    ok, kept, after = json.loads(out.stdout)
    assert ok and kept > 120  # the spike stays resident without a trim ...
    assert after < 50  # ... and a trim brings the resident size back within 50 MiB
