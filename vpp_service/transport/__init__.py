"""Moving frames and results between processes: the layer under the source and sink plugins.

- :mod:`.wire` -- msgpack wire format v1 (encode/decode, full validation) and topic names.
- :mod:`.msgview` -- zero-copy msgpack decoding used by :mod:`.wire`.
- :mod:`.sync` -- separate-topics synchronizer (exact / approximate).
- :mod:`.shm` -- publishing large payloads from a Zenoh shared-memory pool.

Importing this package imports none of them; it depends only on the core
(:mod:`vpp_service.frame`), never on sources, sinks or the service.
"""
