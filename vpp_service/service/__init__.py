"""The streaming service: it composes sources, the fusion step and sinks, and runs them.

- :mod:`.config` -- the TOML service configuration, validated before start.
- :mod:`vpp_service.fusion` -- the per-frame processing step it runs (one layer down).
- :mod:`.pipeline` -- threaded ingest -> process -> sink pipeline with counters.
- :mod:`.app` -- builds the pipeline from a config and runs it.
- :mod:`.allocator` -- process memory tuning the service applies at start.

The wire format, topic sync and shared-memory publishing live one layer down,
in :mod:`vpp_service.transport`.
"""
