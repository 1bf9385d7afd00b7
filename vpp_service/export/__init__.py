"""Tools that turn a network's checkpoint into the ONNX model and card the network matchers run.

- :mod:`~vpp_service.export.psmnet`: PSMNet in PyTorch (``vpp-service models export psmnet``;
  the ``export`` extra). torch is imported there at module level: import it only for an export.
"""
