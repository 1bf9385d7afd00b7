"""Frame sources (Zenoh, files, simulator) and the depth-sensor / synthetic-scene simulators."""
