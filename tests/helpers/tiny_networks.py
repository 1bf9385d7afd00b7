"""Tiny ONNX graphs with known answers, built with the ``onnx`` helper API, for the network matchers' tests.

* :func:`sad_stereo` - a stereo "network": per-pixel SAD over the channels for
  every shift ``d = 0 .. D-1`` of the right image, then ArgMin over ``d``.
  On a pair whose right view is the left one shifted by ``s`` whole pixels of
  random texture, the cost is exactly 0 at ``d = s`` (and nowhere else, with
  overwhelming probability), so its output is exactly ``s`` wherever
  ``x >= D`` - whatever the normalisation.
* :func:`echo` - outputs one channel of its left input (``1 x 1 x H x W``):
  shows exactly what the matcher fed the network (colour order, scale,
  mean/std, padding and where the image sits in the tensor).
* :func:`nan_output` - outputs NaN everywhere.
* :func:`sad_stereo_io` - the SAD network behind the I/O a card can describe:
  one concatenated input, an extra input added to the answer, an output at
  1/stride resolution, float16 tensors.
"""

from __future__ import annotations

from pathlib import Path

import onnx
from onnx import TensorProto, helper

OPSET = 17


def _inputs(names: tuple[str, str], channels: int, size: tuple[int, int] | None) -> list[onnx.ValueInfoProto]:
    h, w = size if size is not None else ("H", "W")
    return [helper.make_tensor_value_info(n, TensorProto.FLOAT, [1, channels, h, w]) for n in names]


def _save(nodes, inputs, outputs, inits, path: Path) -> Path:
    graph = helper.make_graph(nodes, "tiny", inputs, outputs, initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], ir_version=8)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _const(name: str, values: list[int]) -> onnx.TensorProto:
    return helper.make_tensor(name, TensorProto.INT64, [len(values)], values)


def sad_stereo(
    path: Path,
    max_disparity: int,
    *,
    channels: int = 3,
    size: tuple[int, int] | None = None,
    names: tuple[str, str] = ("left", "right"),
    output: str = "disparity",
    window: int = 1,
) -> Path:
    """Write the SAD + ArgMin network (output ``1 x H x W`` float32) to ``path``; ``size`` fixes H x W.

    ``window`` > 1 sums the costs over a ``window x window`` box (zero-padded) before the ArgMin: one
    channel needs it (a single byte matches a wrong shift by chance too often).
    """
    nodes, inits = _sad_nodes(max_disparity, names, output, window)
    h, w = size if size is not None else ("H", "W")
    out = helper.make_tensor_value_info(output, TensorProto.FLOAT, [1, h, w])
    return _save(nodes, _inputs(names, channels, size), [out], inits, path)


def _sad_nodes(
    max_disparity: int, names: tuple[str, str], output: str, window: int
) -> tuple[list[onnx.NodeProto], list[onnx.TensorProto]]:
    """The SAD + ArgMin nodes from the inputs ``names`` to the float32 ``output`` (``1 x H x W``)."""
    nodes, inits = [], [_const("axes1", [1]), _const("axis3", [3]), _const("zero", [0])]
    costs = []
    for d in range(max_disparity):
        if d == 0:
            shifted = names[1]
        else:
            inits += [_const(f"pads{d}", [0, 0, 0, d, 0, 0, 0, 0]), _const(f"end{d}", [-d])]
            nodes.append(helper.make_node("Pad", [names[1], f"pads{d}"], [f"padded{d}"], mode="constant"))
            nodes.append(helper.make_node("Slice", [f"padded{d}", "zero", f"end{d}", "axis3"], [f"shift{d}"]))
            shifted = f"shift{d}"
        nodes += [
            helper.make_node("Sub", [names[0], shifted], [f"diff{d}"]),
            helper.make_node("Abs", [f"diff{d}"], [f"abs{d}"]),
            helper.make_node("ReduceSum", [f"abs{d}", "axes1"], [f"cost{d}"], keepdims=1),
        ]
        costs.append(f"cost{d}")
    nodes += [
        helper.make_node("Concat", costs, ["raw_volume"], axis=1),
    ]
    if window > 1:
        r = window // 2
        nodes.append(
            helper.make_node("AveragePool", ["raw_volume"], ["volume"], kernel_shape=[window] * 2, pads=[r] * 4)
        )
    else:
        nodes.append(helper.make_node("Identity", ["raw_volume"], ["volume"]))
    nodes += [
        helper.make_node("ArgMin", ["volume"], ["best"], axis=1, keepdims=0),
        helper.make_node("Cast", ["best"], [output], to=TensorProto.FLOAT),
    ]
    return nodes, inits


def sad_stereo_io(
    path: Path,
    max_disparity: int,
    *,
    concat: str = "",
    bias: str = "",
    stride: int = 1,
    half: bool = False,
) -> Path:
    """Write the SAD network (3 channels, window 1) behind the I/O forms of a card.

    Parameters
    ----------
    concat : str
        "" (inputs ``left``, ``right``), or the one input taking both, ``1 x 6 x H x W``.
    bias : str
        "" or the name of an int64 scalar input added to the answer.
    stride : int
        The output keeps every ``stride``-th row and column (``1 x H/s x W/s``).
    half : bool
        Image inputs and the output are float16 (cast to float32 inside).
    """
    ftype = TensorProto.FLOAT16 if half else TensorProto.FLOAT
    channels = 6 if concat else 3
    fed = [concat] if concat else ["left_in", "right_in"]
    inputs = [helper.make_tensor_value_info(n, ftype, [1, channels, "H", "W"]) for n in fed]
    nodes = [helper.make_node("Cast", [n], [f"{n}_f"], to=TensorProto.FLOAT) for n in fed]
    inits = [_const("c0", [0]), _const("c3", [3]), _const("c6", [6]), _const("ch", [1])]
    if concat:
        nodes += [
            helper.make_node("Slice", [f"{concat}_f", "c0", "c3", "ch"], ["left"]),
            helper.make_node("Slice", [f"{concat}_f", "c3", "c6", "ch"], ["right"]),
        ]
    else:
        nodes += [helper.make_node("Identity", [f"{n}_f"], [n.removesuffix("_in")]) for n in fed]
    sad, sad_inits = _sad_nodes(max_disparity, ("left", "right"), "answer", 1)
    nodes += sad
    inits += sad_inits
    last = "answer"
    if bias:
        inputs.append(helper.make_tensor_value_info(bias, TensorProto.INT64, []))
        nodes += [
            helper.make_node("Cast", [bias], ["bias_f"], to=TensorProto.FLOAT),
            helper.make_node("Add", [last, "bias_f"], ["biased"]),
        ]
        last = "biased"
    if stride > 1:
        inits += [_const("hw_start", [0, 0]), _const("hw_end", [1 << 30, 1 << 30]), _const("hw_axes", [1, 2])]
        inits.append(_const("hw_steps", [stride, stride]))
        nodes.append(helper.make_node("Slice", [last, "hw_start", "hw_end", "hw_axes", "hw_steps"], ["strided"]))
        last = "strided"
    nodes.append(helper.make_node("Cast", [last], ["disparity"], to=ftype))
    out = helper.make_tensor_value_info("disparity", ftype, [1, "H2", "W2"])
    return _save(nodes, inputs, [out], inits, path)


def echo(path: Path, channel: int = 0, *, channels: int = 3) -> Path:
    """Write a network whose output (``1 x 1 x H x W``) is channel ``channel`` of its left input."""
    inits = [_const("c0", [channel]), _const("c1", [channel + 1]), _const("axis1", [1])]
    nodes = [
        helper.make_node("Slice", ["left", "c0", "c1", "axis1"], ["picked"]),
        helper.make_node("Add", ["picked", "right_zero"], ["disparity"]),
        # the right input must be used: multiply it by 0 and add (keeps both inputs in the graph)
        helper.make_node("Slice", ["right", "c0", "c1", "axis1"], ["rpicked"]),
        helper.make_node("Mul", ["rpicked", "zero_f"], ["right_zero"]),
    ]
    inits.append(helper.make_tensor("zero_f", TensorProto.FLOAT, [], [0.0]))
    out = helper.make_tensor_value_info("disparity", TensorProto.FLOAT, [1, 1, "H", "W"])
    nodes = [nodes[0], nodes[2], nodes[3], nodes[1]]  # topological order
    return _save(nodes, _inputs(("left", "right"), channels, None), [out], inits, path)


def nan_output(path: Path) -> Path:
    """Write a network whose output (``1 x H x W``) is 0 / 0 = NaN everywhere."""
    inits = [_const("axes1", [1])]
    nodes = [
        helper.make_node("Sub", ["left", "right"], ["d"]),
        helper.make_node("Sub", ["d", "d"], ["z"]),
        helper.make_node("Div", ["z", "z"], ["nan4"]),
        helper.make_node("ReduceSum", ["nan4", "axes1"], ["disparity"], keepdims=0),
    ]
    out = helper.make_tensor_value_info("disparity", TensorProto.FLOAT, [1, "H", "W"])
    return _save(nodes, _inputs(("left", "right"), 3, None), [out], inits, path)
