"""Speaking ROS 2 over Zenoh as an ``rmw_zenoh`` node does, with no ROS installation.

The contract these modules implement (key expressions, CDR payloads, attachments,
liveliness tokens, type hashes) is described in ``docs/ros2.md``:

- :mod:`.errors` -- :class:`~.errors.Ros2Error`, a rejected message with a named cause.
- :mod:`.keys` -- topic key expressions, type names and hashes, QoS strings, liveliness tokens.
- :mod:`.attachment` -- the per-sample attachment (current 33-byte and older labelled format).
- :mod:`.messages` -- CDR <-> numpy for ``Image``, ``CameraInfo``, ``PointCloud2``,
  ``DisparityImage`` and ``TFMessage`` (the ``rosbags`` type store does the CDR), with size bounds.
- :mod:`.cloud` -- a point cloud moved into the left camera and projected into a sparse depth map.
- :mod:`.tf` -- the static transform tree (``/tf_static``) and the chain between two frames.

Importing this package imports none of them.
"""
