"""vpp-service: Virtual Pattern Projection stereo-depth fusion as a service.

Packages, by architectural role:

- :mod:`vpp_service.vpp` -- the VPP algorithm (Cython kernels + typed wrappers).
- :mod:`vpp_service.matchers` -- stereo matchers registered by name.
- :mod:`vpp_service.datasets` -- readers for real stereo benchmarks.
- :mod:`vpp_service.sources` -- frame sources (Zenoh, files, simulator) and the
  depth-sensor / synthetic-scene simulators.
- :mod:`vpp_service.sinks` -- result sinks (Zenoh, Rerun, files).
- :mod:`vpp_service.evaluation` -- metrics and the benchmark harness.
- :mod:`vpp_service.transport` -- wire format, message view, topic sync, shared-memory publishing.
- :mod:`vpp_service.fusion` -- the per-frame step (sparse depth -> VPP -> matcher -> depth, metrics).
- :mod:`vpp_service.queueing` -- the bounded queue with its worker thread (pipeline stages, buffering sinks).
- :mod:`vpp_service.threads` -- the OpenMP thread-count and wait policy of the kernels.
- :mod:`vpp_service.service` -- config, app and the streaming pipeline (composes the rest).
- :mod:`vpp_service.cli` -- the ``vpp-service`` command.

Importing the package has no side effects (it does not touch the environment);
the ``vpp-service`` command sets the OpenMP wait policy
(:func:`vpp_service.threads.configure_openmp`) before it loads any kernel.
"""

__version__ = "0.1.0"
