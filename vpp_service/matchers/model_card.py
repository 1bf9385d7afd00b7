"""The model card of a stereo network: how to feed it, how to read its output, which VPP setting suits it.

A network exported to ONNX says nothing about the colour order, normalisation,
padding or disparity range it was trained with; the card says it. It is a
small TOML file beside the model (``psmnet.onnx`` -> ``psmnet.toml``), a table
of the same keys in the matcher's config (``matcher.card``), or one of the
cards shipped with the package (``vpp_service/matchers/cards/NAME.toml``: each
registers a matcher ``NAME``, the ``onnx`` matcher bound to that card)::

    name = "psmnet_kitti2015"
    # inputs: two images, 1 x C x H x W each (or one tensor of both, concat_input)
    left_input = "left"  # graph input names
    right_input = "right"
    concat_input = ""  # "": separate inputs; else the input taking [left, right] on channels, 1 x 2C x H x W
    extra_inputs = {}  # constant inputs fed with every pair: name = number or list (int -> int64, else dtype)
    dtype = "float32"  # float32 | float16: the image tensors in, the disparity out
    colour = "rgb"  # rgb | bgr | gray: channels the network takes
    scale = 0.00392156862745098  # pixel value * scale, then (x - mean) / std
    mean = [0.485, 0.456, 0.406]
    std = [0.229, 0.224, 0.225]
    pad_multiple = 16  # dynamic size: H and W padded up to a multiple
    pad_rows = "top"  # top | bottom: where the padding rows go
    pad_cols = "right"  # left | right: where the padding columns go
    min_size = [256, 256]  # dynamic size: smaller images are padded up to [H, W] ([] = none)
    input_size = []  # [] dynamic; [H, W] fixed: resize in, rescale the disparity out
    # output
    output = "disparity"  # graph output ("" = its only output)
    output_layout = "1HW"  # 1HW | 11HW | HW
    output_stride = 1  # the output grid is the input's / stride (upsampled back, values kept)
    output_scale = 1.0  # disparity = output * output_scale (-1 for a flow-like output)
    max_disparity = 192  # the network's disparity range (pixels at its input size)
    # where it comes from
    model_file = "psmnet_kitti2015.onnx"  # a shipped card: the file looked for in the models folder
    howto = "..."  # a shipped card: how to get that file (the error when it is missing says it)
    licence = "..."
    provenance = "..."

    [vpp]  # the VPP setting measured for this network, used where the user set nothing
    uniform_patch = true
    patch = 5
    alpha = 0.4
    occlusion = "fgd"

Padding is zeros after normalisation (what the network sees as the mean
colour); the output is cropped back to the image. :func:`read_card` validates
a file, :func:`card_from_mapping` a table; :func:`find_card` looks for the
file beside a model; :func:`shipped_card` reads a card of the package.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np

from vpp_service.settings import (
    Each,
    NonEmpty,
    OptionError,
    Options,
    Range,
    Satisfies,
    SettingsError,
    from_mapping,
    reject,
)
from vpp_service.vpp import VPPConfig

#: Layouts of the disparity output (batch 1).
OUTPUT_LAYOUTS = ("1HW", "11HW", "HW")

#: Tensor types of the image inputs and the disparity output.
DTYPES = ("float32", "float16")

#: The VPP setting of a card without a ``[vpp]`` table: one random value per 5 x 5 patch (the paper's variant
#: iv), alpha 0.4, FGD occlusion handling, the setting measured for networks (docs/deep-matchers.md).
NETWORK_VPP: Mapping[str, object] = {"uniform_patch": True, "patch": 5, "alpha": 0.4, "occlusion": "fgd"}


#: A finite number other than 0 (a scale factor).
_NON_ZERO = Satisfies(lambda v: v != 0, "a non-zero number")
#: A graph tensor name, or "" (unset).
_NAME = Satisfies(lambda v: v == "" or bool(v.strip()), "a graph tensor name (not blank)")


@dataclass(frozen=True)
class ModelCard(Options):
    """How a stereo network is fed and read (see the module docstring for the TOML form).

    Attributes
    ----------
    name : str
        Short model name (reports, ``models list``).
    left_input, right_input : str
        Graph input names of the left and right image (each ``1 x C x H x W``).
    concat_input : str
        "" (separate inputs), or the graph input that takes both images
        concatenated on the channel axis, left first (``1 x 2C x H x W``);
        ``left_input`` / ``right_input`` are then unused.
    extra_inputs : dict of str to number or list
        Constant inputs fed with every pair (e.g. an iteration count): an
        integer value is fed as int64, a real one as ``dtype``.
    dtype : {"float32", "float16"}
        Tensor type of the image inputs and of the disparity output (read as float32).
    output : str
        Graph output name of the disparity; "" = the graph's only output.
    colour : {"rgb", "bgr", "gray"}
        Channels the network takes (gray: ``C = 1``; an RGB image is converted
        with the luminance weights, a gray one is replicated for rgb/bgr).
    scale : float
        Pixel values (0..255) are multiplied by it before the mean/std step.
    mean, std : tuple of float
        Per-channel normalisation ``(x * scale - mean) / std``, one value per
        channel (or one for all); std > 0.
    pad_multiple : int
        Dynamic input: height and width are padded up to a multiple of it (>= 1).
    pad_rows : {"top", "bottom"}
        Where the padding rows go (the output is cropped back).
    pad_cols : {"left", "right"}
        Where the padding columns go.
    min_size : tuple of int
        ``()`` or ``(H, W)``: the smallest input a dynamic network takes
        (pooling layers); smaller images are padded up to it.
    input_size : tuple of int
        ``()`` for a dynamic input size; ``(H, W)`` for a network with a fixed
        input: the pair is resized to it and the disparity resized back and
        multiplied by ``W_image / W``.
    output_layout : {"1HW", "11HW", "HW"}
        Shape of the disparity output.
    output_stride : int
        The output's grid is the input tensor's divided by it (a network that
        answers at 1/4 resolution: 4); it is upsampled back (bilinear), its
        values unchanged: ``output_scale`` says what they are in input pixels.
    output_scale : float
        Disparity = output * output_scale (non-zero; -1 for a network that
        outputs the negative x-flow).
    max_disparity : int
        The network's disparity range in pixels at its input size (its cost
        volume's depth): the matcher accepts any ``max_disparity`` up to it.
    model_file : str
        The model file a shipped card's matcher looks for in the models folder
        when ``model`` is not given ("" = ``model`` is required).
    howto : str
        How to get ``model_file`` (one sentence; the missing-file error says it).
    licence, provenance : str
        Where the weights come from and under which terms (shown by ``models list``).
    vpp : dict
        :class:`~vpp_service.vpp.VPPConfig` fields measured to suit this network
        (the ``[vpp]`` table; default :data:`NETWORK_VPP`): ``eval`` and the
        service apply them where the user set nothing.
    """

    name: str = ""
    left_input: Annotated[str, NonEmpty()] = "left"
    right_input: Annotated[str, NonEmpty()] = "right"
    output: str = ""
    colour: Literal["rgb", "bgr", "gray"] = "rgb"
    scale: Annotated[float, Range(), _NON_ZERO] = 1.0 / 255.0
    mean: Annotated[tuple[float, ...], Each(Range())] = (0.0,)
    std: Annotated[tuple[float, ...], Each(Range(0.0, lo_open=True))] = (1.0,)
    pad_multiple: Annotated[int, Range(1, 1024)] = 1
    pad_rows: Literal["top", "bottom"] = "bottom"
    pad_cols: Literal["left", "right"] = "right"
    min_size: Annotated[tuple[int, ...], Each(Range(1))] = ()
    input_size: Annotated[tuple[int, ...], Each(Range(1, 16384))] = ()
    output_layout: Literal["1HW", "11HW", "HW"] = "1HW"
    output_scale: Annotated[float, Range(), _NON_ZERO] = 1.0
    max_disparity: Annotated[int, Range(1, 4096)] = 192
    concat_input: Annotated[str, _NAME] = ""
    extra_inputs: dict[str, Any] = field(default_factory=dict)
    dtype: Literal["float32", "float16"] = "float32"
    output_stride: Annotated[int, Range(1, 64)] = 1
    model_file: str = ""
    howto: str = ""
    licence: str = ""
    provenance: str = ""
    vpp: dict[str, Any] = field(default_factory=lambda: dict(NETWORK_VPP))

    def cross_check(self) -> None:
        """Distinct inputs, one mean/std per channel (or one), sizes of two sides, fixed sizes padded."""
        if self.left_input == self.right_input:
            raise reject("right_input", self.right_input, f"a name other than left_input ({self.left_input!r})")
        for key in ("mean", "std"):
            if len(getattr(self, key)) not in (1, self.channels):
                raise reject(key, list(getattr(self, key)), f"1 or {self.channels} values (colour {self.colour})")
        for key in ("min_size", "input_size"):
            if len(getattr(self, key)) not in (0, 2):
                raise reject(key, list(getattr(self, key)), "[] or [H, W]")
        if self.input_size and self.min_size:
            raise reject("min_size", list(self.min_size), "[] when input_size fixes the size")
        if any(v % self.pad_multiple for v in self.input_size):
            raise reject("input_size", list(self.input_size), f"multiples of pad_multiple ({self.pad_multiple})")
        self._check_io()
        self._check_vpp()

    def _check_vpp(self) -> None:
        """The ``[vpp]`` table: VPPConfig fields (the error names ``vpp.key``)."""
        from_mapping(VPPConfig, self.vpp, "vpp")

    def _check_io(self) -> None:
        """The I/O keys beyond the two image inputs: the output stride divides the size; extra inputs."""
        for v in self.input_size or (self.pad_multiple,):
            if v % self.output_stride:
                size = f"input_size {list(self.input_size)}" if self.input_size else f"pad_multiple {v}"
                raise reject("output_stride", self.output_stride, f"a divisor of the input size ({size})")
        for name, value in self.extra_inputs.items():
            if not name.strip():
                raise reject("extra_inputs", name, "graph tensor names (not blank)")
            if name in self.image_inputs:
                raise reject(f"extra_inputs.{name}", value, "a name that is not an image input of the card")
            a = np.asarray(value)
            if a.dtype.kind not in "iuf" or not np.isfinite(a).all():
                raise reject(f"extra_inputs.{name}", value, "a finite number or a list of them")

    @property
    def image_inputs(self) -> tuple[str, ...]:
        """The graph inputs fed with the images: ``(concat_input,)`` or ``(left_input, right_input)``."""
        return (self.concat_input,) if self.concat_input else (self.left_input, self.right_input)

    @property
    def input_channels(self) -> int:
        """Channels of each image input tensor: :attr:`channels`, twice that for a concatenated input."""
        return 2 * self.channels if self.concat_input else self.channels

    def extra_feeds(self) -> dict[str, np.ndarray]:
        """The ``extra_inputs`` as arrays: integers as int64, reals as :attr:`dtype`."""
        out = {}
        for name, value in self.extra_inputs.items():
            a = np.asarray(value)
            out[name] = a.astype(np.int64) if a.dtype.kind in "iu" else a.astype(self.dtype)
        return out

    @property
    def channels(self) -> int:
        """Channels of each input tensor: 1 for gray, else 3."""
        return 1 if self.colour == "gray" else 3

    @property
    def fixed(self) -> bool:
        """True for a network with a fixed input size."""
        return bool(self.input_size)

    def range_at(self, width: int) -> float:
        """The network's disparity range in pixels of an image ``width`` columns wide (fixed size: rescaled)."""
        return self.max_disparity * (width / self.input_size[1]) if self.fixed else float(self.max_disparity)


def card_from_mapping(data: Any, section: str, base: ModelCard | None = None) -> ModelCard:
    """Validate a table of card keys into a :class:`ModelCard`.

    Parameters
    ----------
    data : Mapping
        Card keys (see :class:`ModelCard`); missing keys come from ``base``.
    section : str
        Prefix of error messages (e.g. ``"matcher.onnx.card"`` or the file name).
    base : ModelCard or None
        The card the keys override (None: the defaults).

    Raises
    ------
    SettingsError
        Unknown key, wrong type or out-of-range value, naming ``section.key``.
    """
    merged: dict[str, Any] = {} if base is None else {f.name: getattr(base, f.name) for f in fields(base)}
    if not isinstance(data, dict):
        raise OptionError(section, type(data).__name__, "a table of card keys")
    merged.update(data)
    return from_mapping(ModelCard, merged, section)


def read_card(path: str | Path, base: ModelCard | None = None) -> ModelCard:
    """Read and validate a card file (TOML).

    Raises
    ------
    FileNotFoundError
        No such file.
    SettingsError
        Invalid TOML or an invalid key, naming the file.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"model card: no such file: {p}")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"card[{p}]: invalid TOML: {exc}") from None
    return card_from_mapping(data, f"card[{p}]", base)


def card_path(model: str | Path) -> Path:
    """Where the card of ``model`` lives: the same path with the suffix ``.toml``."""
    return Path(model).with_suffix(".toml")


def find_card(model: str | Path) -> Path | None:
    """The card file beside ``model`` when there is one, else None."""
    p = card_path(model)
    return p if p.is_file() else None


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return repr(v) if isinstance(v, float) else str(v)


def card_to_toml(card: ModelCard) -> str:
    """The card as TOML text (what :func:`read_card` reads back): its keys, then the ``[vpp]`` table."""
    lines = [f"{f.name} = {_toml_value(getattr(card, f.name))}" for f in fields(card) if f.name != "vpp"]
    lines += ["", "[vpp]", *(f"{k} = {_toml_value(v)}" for k, v in card.vpp.items())]
    return "\n".join(lines) + "\n"


#: The package folder of the shipped cards (``NAME.toml``: the card of the matcher ``NAME``).
CARDS_PACKAGE = "vpp_service.matchers"
CARDS_FOLDER = "cards"


def shipped_cards() -> dict[str, Path]:
    """The cards shipped with the package, by name (the file's stem), sorted."""
    folder = resources.files(CARDS_PACKAGE).joinpath(CARDS_FOLDER)
    found = {Path(str(f)).stem: Path(str(f)) for f in folder.iterdir() if f.name.endswith(".toml")}
    return dict(sorted(found.items()))


def shipped_card(name: str) -> ModelCard:
    """The shipped card ``name`` (see :func:`shipped_cards`).

    Raises
    ------
    ValueError
        No such card (lists the shipped ones).
    """
    cards = shipped_cards()
    if name not in cards:
        raise ValueError(f"no shipped model card {name!r}; shipped: {', '.join(cards) or '(none)'}")
    return read_card(cards[name])


__all__ = [
    "DTYPES",
    "NETWORK_VPP",
    "OUTPUT_LAYOUTS",
    "ModelCard",
    "card_from_mapping",
    "card_path",
    "card_to_toml",
    "find_card",
    "read_card",
    "shipped_card",
    "shipped_cards",
]
