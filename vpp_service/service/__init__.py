"""The streaming service: wire format, configuration, topic sync and the pipeline.

- :mod:`.wire` -- msgpack wire format v1 (encode/decode, full validation).
- :mod:`.config` -- the TOML service configuration, validated before start.
- :mod:`.sync` -- separate-topics synchronizer (exact / approximate).
- :mod:`.fusion` -- the per-frame processing step (depth -> VPP -> matcher).
- :mod:`.pipeline` -- threaded ingest -> process -> sink pipeline with counters.
"""
