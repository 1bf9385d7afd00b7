"""vpp-service: Virtual Pattern Projection stereo-depth fusion as a service.

Packages, by architectural role:

- :mod:`vpp_service.vpp` -- the VPP algorithm (Cython kernels + typed wrappers).
- :mod:`vpp_service.matchers` -- stereo matchers registered by name.
- :mod:`vpp_service.datasets` -- readers for real stereo benchmarks.
- :mod:`vpp_service.sources` -- frame sources (Zenoh, files, simulator) and the
  depth-sensor / synthetic-scene simulators.
- :mod:`vpp_service.sinks` -- result sinks (Zenoh, Rerun, files).
- :mod:`vpp_service.evaluation` -- metrics and the benchmark harness.
- :mod:`vpp_service.transport` -- wire format, topic sync, shared-memory publishing.
- :mod:`vpp_service.service` -- config and the streaming pipeline (composes the rest).
- :mod:`vpp_service.cli` -- the ``vpp-service`` command.
"""

import os as _os

# OpenMP threads of the kernels sleep as soon as a parallel region ends
# (OMP_WAIT_POLICY=PASSIVE) unless the user chose a policy or a spin count.  A
# streaming service calls the kernels once per frame with idle gaps between; with
# libgomp's default (spin, then sleep) the first region after a gap took 2-8 ms
# on virtualised 2-core hosts, against 0.03 ms when passive (docs/deployment.md,
# "Process tuning", also for the spinning low-latency alternative).  It must be
# set before libgomp loads, i.e. before any kernel module is imported; it has no
# effect if another library loaded OpenMP first.
if "OMP_WAIT_POLICY" not in _os.environ and "GOMP_SPINCOUNT" not in _os.environ:
    _os.environ["OMP_WAIT_POLICY"] = "PASSIVE"

__version__ = "0.1.0"
