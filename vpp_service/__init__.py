"""vpp-service: Virtual Pattern Projection stereo-depth fusion as a service.

Packages, by architectural role:

- :mod:`vpp_service.vpp` -- the VPP algorithm (Cython kernels + typed wrappers).
- :mod:`vpp_service.matchers` -- stereo matchers registered by name.
- :mod:`vpp_service.datasets` -- readers for real stereo benchmarks.
- :mod:`vpp_service.sources` -- frame sources (Zenoh, files, simulator) and the
  depth-sensor / synthetic-scene simulators.
- :mod:`vpp_service.sinks` -- result sinks (Zenoh, Rerun, files).
- :mod:`vpp_service.evaluation` -- metrics and the benchmark harness.
- :mod:`vpp_service.service` -- wire format, config and the streaming pipeline.
- :mod:`vpp_service.cli` -- the ``vpp-service`` command.
"""

__version__ = "0.1.0"
