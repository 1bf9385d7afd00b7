"""Stereo networks exported to ONNX as matchers: ``onnx`` (any network, with its card) and one per shipped card.

Every card shipped in ``vpp_service/matchers/cards/`` (``psmnet.toml``)
registers a matcher of its name: the ``onnx`` matcher bound to that card, which
looks for the card's ``model_file`` in the models folder when ``model`` is not
given. Adding a network is adding a card file.

The network is a black box the pair goes through unchanged (VPP paints the
pair before it, as for any matcher):

1. **In** (:func:`to_tensor`): the image in the card's colour order, scaled and
   normalised (``(x * scale - mean) / std``), as ``1 x C x H x W`` of the
   card's ``dtype``, zero-padded to a multiple of ``pad_multiple`` (and at
   least ``min_size``) on the card's sides; a network with a fixed input size
   gets the pair resized to it instead. The two images go to the card's two
   inputs, or concatenated on channels to its ``concat_input``, with its
   ``extra_inputs`` beside them.
2. **Network**: :mod:`~vpp_service.matchers.inference` (OpenVINO on CPU, ONNX
   Runtime on CUDA or the ``providers`` given; f32 unless ``precision`` asks
   otherwise), or a Triton
   Inference Server (``engine = "triton"``, :mod:`~vpp_service.matchers.triton`):
   the tensors cross the network, the pre- and post-processing stay here.
3. **Out** (:func:`from_output`): the disparity upsampled to the input grid
   (``output_stride`` > 1), cropped back (fixed size: resized back and
   multiplied by ``W_image / W_network``), times the card's
   ``output_scale``. An output with NaN or inf is an error. Values outside
   ``0 .. max_disparity`` become NaN (invalid), the search range every
   matcher shares.

Disparity range: the network searches its own range (the card's
``max_disparity``, 192 for PSMNet) whatever it is asked; ``max_disparity``
may be anything up to it (``"auto"`` and ``eval``'s per-scene default
included: they are capped at :attr:`OnnxMatcher.max_range`) and only limits
which outputs are valid. More than the network's range is an error.

Guided stereo needs the matcher's cost volume, which a network does not expose:
``supports_guidance`` is False (``eval --methods guided`` says so).

Options (``[matcher]``, ``--matcher-opt KEY=VALUE``): ``model`` (the
``.onnx``: a path, or a name in the models folder,
:func:`~vpp_service.matchers.model_store.models_dir`, when the working
directory has no such file; a shipped card's matcher looks there for the
card's ``model_file`` when it is not given), ``card_file`` / ``card`` (the
card: a TOML file, or a table of keys that override it; default the ``.toml``
beside the model, else the shipped card),
``device``, ``engine``, ``precision``, ``threads`` (0 = the project's policy).

With ``engine = "triton"`` no local file is needed: ``url`` (one ``host:port``
or a list), ``model`` (the model's name on the server; default the card's
``name``), ``model_version``, TLS (``ssl``, ``root_certificates``,
``private_key``, ``certificate_chain``: PEM files), ``timeout_ms``, ``retry_s``
and ``in_flight`` (frames the service keeps on the servers at once).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, cast

import cv2
import numpy as np

from vpp_service.matchers.base import MATCHERS, DisparityRangeError, Matcher, MatcherOptions, MatcherRuntime
from vpp_service.matchers.inference import Engine, open_engine
from vpp_service.matchers.inputs import check_pair, to_gray
from vpp_service.matchers.model_card import (
    NETWORK_VPP,
    ModelCard,
    card_from_mapping,
    find_card,
    read_card,
    shipped_card,
    shipped_cards,
)
from vpp_service.matchers.model_store import MODELS_ENV, find_model, models_dir
from vpp_service.matchers.triton import TritonEngine, TritonSettings, metadata_mismatches, open_triton
from vpp_service.settings import Each, NonEmpty, Range, Unique, reject
from vpp_service.threads import resolve_threads


@dataclass(frozen=True)
class Layout:
    """Where an image sits in the network's input tensor (returned by :func:`to_tensor`).

    Attributes
    ----------
    height, width : int
        The image size.
    top, left : int
        Offset of the image in the padded tensor (dynamic size).
    tensor_height, tensor_width : int
        The tensor's spatial size.
    resized : bool
        True when the image was resized to a fixed input size (no padding).
    """

    height: int
    width: int
    top: int
    left: int
    tensor_height: int
    tensor_width: int
    resized: bool = False


def _round_up(v: int, m: int) -> int:
    return -(-v // m) * m


def tensor_layout(height: int, width: int, card: ModelCard) -> Layout:
    """The input tensor size and the image's place in it for an ``height x width`` image."""
    if card.fixed:
        th, tw = card.input_size
        return Layout(height, width, 0, 0, th, tw, resized=True)
    m = card.pad_multiple
    min_h, min_w = card.min_size or (1, 1)
    th, tw = _round_up(max(height, min_h), m), _round_up(max(width, min_w), m)
    top = th - height if card.pad_rows == "top" else 0
    left = tw - width if card.pad_cols == "left" else 0
    return Layout(height, width, top, left, th, tw)


def _channels(img: np.ndarray, card: ModelCard) -> np.ndarray:
    """``img`` as H x W x C uint8 in the card's colour order."""
    if card.colour == "gray":
        return to_gray(img)[:, :, None]
    if img.ndim == 2 or img.shape[2] == 1:
        g = img if img.ndim == 2 else img[:, :, 0]
        return np.repeat(g[:, :, None], 3, axis=2)
    return img[:, :, ::-1] if card.colour == "bgr" else img


def to_tensor(img: np.ndarray, card: ModelCard, layout: Layout | None = None) -> tuple[np.ndarray, Layout]:
    """One image as the network's input: ``1 x C x H' x W'`` float32, normalised and padded (or resized).

    Parameters
    ----------
    img : ndarray
        H x W or H x W x C (C = 1 | 3, RGB) uint8.
    card : ModelCard
        Colour order, normalisation, padding or fixed size, dtype.
    layout : Layout or None
        The layout to use (default :func:`tensor_layout` of the image).

    Returns
    -------
    tensor : ndarray
        Of the card's ``dtype``; padding is 0 (after normalisation).
    layout : Layout
    """
    h, w = img.shape[:2]
    lay = layout or tensor_layout(h, w, card)
    src = _channels(img, card)
    if lay.resized:
        src = cv2.resize(src, (lay.tensor_width, lay.tensor_height), interpolation=cv2.INTER_LINEAR)
        if src.ndim == 2:
            src = src[:, :, None]
    c = card.channels
    std = np.broadcast_to(np.asarray(card.std, np.float32), (c,))
    mean = np.broadcast_to(np.asarray(card.mean, np.float32), (c,))
    gain = (np.float32(card.scale) / std).reshape(c, 1, 1)
    offset = (-mean / std).reshape(c, 1, 1)
    out = np.zeros((1, c, lay.tensor_height, lay.tensor_width), np.float32)
    sh, sw = src.shape[:2]
    view = out[0, :, lay.top : lay.top + sh, lay.left : lay.left + sw]
    np.multiply(src.transpose(2, 0, 1), gain, out=view)  # uint8 x float32 -> float32, written in place
    view += offset
    return (out if card.dtype == "float32" else out.astype(card.dtype)), lay


def network_feeds(left: np.ndarray, right: np.ndarray, card: ModelCard) -> dict[str, np.ndarray]:
    """The graph inputs for a pair of image tensors (:func:`to_tensor`): the card's image inputs and extra inputs."""
    images = (
        {card.concat_input: np.concatenate((left, right), axis=1)}
        if card.concat_input
        else {card.left_input: left, card.right_input: right}
    )
    return {**images, **card.extra_feeds()}


def from_output(raw: np.ndarray, card: ModelCard, layout: Layout, name: str = "network") -> np.ndarray:
    """The H x W float32 disparity of the image from the network's raw output.

    Raises
    ------
    ValueError
        The output's shape does not match the card's layout and the input
        size, or it holds NaN / inf (one line, naming ``name``).
    """
    want = (layout.tensor_height, layout.tensor_width)
    grid = (want[0] // card.output_stride, want[1] // card.output_stride)
    lead = {"1HW": (1,), "11HW": (1, 1), "HW": ()}[card.output_layout]
    if tuple(raw.shape) != (*lead, *grid):
        stride = f", output_stride {card.output_stride}" if card.output_stride > 1 else ""
        raise ValueError(
            f"{name}: output shape {tuple(raw.shape)}, expected {(*lead, *grid)} "
            f"(card output_layout {card.output_layout}{stride} at input {want[0]} x {want[1]})"
        )
    d = raw.reshape(grid)
    if card.output_stride > 1:
        d = cv2.resize(d.astype(np.float32, copy=False), (want[1], want[0]), interpolation=cv2.INTER_LINEAR)
    if layout.resized:
        d = cv2.resize(d.astype(np.float32, copy=False), (layout.width, layout.height), interpolation=cv2.INTER_LINEAR)
        factor = card.output_scale * layout.width / layout.tensor_width
    else:
        d = d[layout.top : layout.top + layout.height, layout.left : layout.left + layout.width]
        factor = card.output_scale
    out = np.array(d, dtype=np.float32, copy=True)
    if factor != 1.0:
        out *= np.float32(factor)
    bad = ~np.isfinite(out)
    if bad.any():
        raise ValueError(f"{name}: the network output has {int(bad.sum())} NaN/inf values (of {out.size})")
    return out


@dataclass(frozen=True)
class OnnxOptions(MatcherOptions):
    """Options of the ``onnx`` matcher (see the module docstring).

    Attributes
    ----------
    model : str
        Path of the ``.onnx`` file (required for ``onnx``; ``psmnet`` looks in
        the models folder when empty). A relative path not in the working
        directory is looked up in the models folder
        (:func:`~vpp_service.matchers.model_store.find_model`). With
        ``engine = "triton"``: the model's name on the server ("" = the
        card's ``name``).
    card_file : str
        Path of the card (TOML); "" = the ``.toml`` beside the model, else the preset's card.
    card : dict
        Card keys that override the card (or are the whole card, when there is no file).
    device : {"auto", "cpu", "cuda"}
        Where the network runs (default auto: CUDA when ONNX Runtime has it, else CPU).
    engine : {"auto", "openvino", "onnxruntime", "triton"}
        Inference engine (auto: OpenVINO on CPU when installed, ONNX Runtime on CUDA;
        triton: a Triton Inference Server, :mod:`~vpp_service.matchers.triton`).
    precision : {"f32", "bf16", "f16"}
        Inference precision (default f32; bf16 / f16 only with OpenVINO).
    providers : tuple of str
        ONNX Runtime's execution providers in order (e.g. ``["TensorrtExecutionProvider",
        "CUDAExecutionProvider"]``); () = from ``device``. Given, they pick ONNX Runtime
        and the device (leave ``engine`` and ``device`` at auto).
    provider_options : dict
        Options per provider (``{CUDAExecutionProvider = {device_id = 1}}``); keys among ``providers``.
    threads : int
        CPU threads (0 = the project's policy, :func:`vpp_service.threads.default_threads`).
    max_disparity : int
        Disparities treated as valid ``0 .. max_disparity - 1``; at most the
        network's range. 0 (default): the network's range (the card's ``max_disparity``).
    url : str or tuple of str
        ``engine = "triton"``: the servers' gRPC endpoints (``host:port``, one or a list).
    model_version : str
        ``engine = "triton"``: the model version ("" = the server's policy).
    ssl : bool
        ``engine = "triton"``: TLS; ``root_certificates``, ``private_key``,
        ``certificate_chain`` are PEM files ("" = none).
    timeout_ms : float
        ``engine = "triton"``: deadline of one request (a server past it is marked down).
    retry_s : float
        ``engine = "triton"``: how long a request waits for a server when none is up.
    in_flight : int
        ``engine = "triton"``: frames matched at once (requests outstanding), 1..64.
    """

    model: str = ""
    card_file: str = ""
    card: dict[str, Any] = field(default_factory=dict)
    device: Literal["auto", "cpu", "cuda"] = "auto"
    engine: Literal["auto", "openvino", "onnxruntime", "triton"] = "auto"
    precision: Literal["f32", "bf16", "f16"] = "f32"
    providers: Annotated[tuple[str, ...], Each(NonEmpty()), Unique()] = ()
    provider_options: dict[str, Any] = field(default_factory=dict)
    threads: Annotated[int, Range(0)] = 0
    url: str | tuple[str, ...] = ""
    model_version: str = ""
    ssl: bool = False
    root_certificates: str = ""
    private_key: str = ""
    certificate_chain: str = ""
    timeout_ms: Annotated[float, Range(1.0, 3_600_000.0)] = 30_000.0
    retry_s: Annotated[float, Range(0.0, 86_400.0)] = 30.0
    in_flight: Annotated[int, Range(1, 64)] = 1

    #: 0: the network's range, set when the card is read.
    max_disparity: Annotated[int, Range(0, 4096)] = 0

    def cross_check(self) -> None:
        """The precision the engine runs, and the Triton-only settings (see :meth:`_check_triton`)."""
        super().cross_check()
        if self.engine == "onnxruntime" and self.precision != "f32":
            raise reject("precision", self.precision, "'f32' with engine 'onnxruntime' (bf16/f16 need 'openvino')")
        self._check_providers()
        self._check_triton()

    def _check_providers(self) -> None:
        """Providers choose ONNX Runtime and the device; options only for listed providers, as tables."""
        if self.providers and (self.engine not in ("auto", "onnxruntime") or self.device != "auto"):
            raise reject(
                "providers",
                list(self.providers),
                f"none with engine {self.engine!r} / device {self.device!r} "
                "(providers choose ONNX Runtime and the device: leave engine and device 'auto')",
            )
        for name, opts in self.provider_options.items():
            if name not in self.providers:
                raise reject(f"provider_options.{name}", opts, f"options of a listed provider {list(self.providers)}")
            if not isinstance(opts, dict):
                raise reject(f"provider_options.{name}", opts, "a table of options")

    @property
    def urls(self) -> tuple[str, ...]:
        """``url`` as a tuple (one or several servers)."""
        return (self.url,) if isinstance(self.url, str) and self.url else tuple(u for u in self.url if u)

    def _check_triton(self) -> None:
        """``url`` host:port items, set with engine 'triton' only; the settings the server decides left alone."""
        for u in (self.url,) if isinstance(self.url, str) else self.url:
            if not isinstance(u, str) or (u and (":" not in u or " " in u)):
                raise reject("url", u, "host:port (or a list of them)")
        if self.engine == "triton" and not self.urls:
            raise reject("url", self.url, "the server's gRPC endpoint, host:port (or a list), with engine 'triton'")
        if self.engine != "triton" and self.urls:
            raise reject("url", self.url, f"'' unless engine is 'triton' (engine is {self.engine!r})")
        if self.engine == "triton" and self.device == "cuda":
            raise reject("device", self.device, "'auto' or 'cpu' with engine 'triton' (the server decides)")
        if self.engine == "triton" and self.precision != "f32":
            raise reject("precision", self.precision, "'f32' with engine 'triton' (the server decides)")
        if self.in_flight > 1 and self.engine != "triton":
            raise reject("in_flight", self.in_flight, "1 unless engine is 'triton' (a local engine runs one frame)")


@MATCHERS.register("onnx")
class OnnxMatcher(Matcher):
    """A stereo network exported to ONNX, fed and read as its model card says.

    Construction resolves the model file and reads the card (cheap, no engine);
    the engine opens on first use (:meth:`engine`), shared by every matcher of
    the same file and settings. After each :meth:`compute`, :attr:`last_timing`
    holds the milliseconds spent in ``pre`` (tensors), ``network`` and ``post``.

    Raises
    ------
    FileNotFoundError
        The model file is missing (a shipped card's matcher: says how to get it).
    ValueError
        No card, an invalid card, or ``max_disparity`` above the network's range.
    """

    name = "onnx"
    Options = OnnxOptions
    options: OnnxOptions
    #: The shipped card this matcher is bound to ("" for ``onnx``: the card comes from a file or the ``card``
    #: option); see :func:`~vpp_service.matchers.model_card.shipped_cards`.
    network: ClassVar[str] = ""

    @classmethod
    def shipped(cls) -> ModelCard | None:
        """The shipped card this matcher is bound to (None for ``onnx``)."""
        return shipped_card(cls.network) if cls.network else None

    @classmethod
    def preferred_vpp(cls, options: MatcherOptions | Mapping[str, object] | None = None) -> Mapping[str, object]:
        """The card's ``[vpp]`` setting (the network's measured best), read without opening the network.

        Where the card cannot be read yet (no model file, no card), the shipped
        card's setting, else :data:`~vpp_service.matchers.model_card.NETWORK_VPP`:
        building the matcher reports what is missing.
        """
        if isinstance(options, MatcherOptions) and not isinstance(options, OnnxOptions):
            raise TypeError(f"{cls.name}: options must be OnnxOptions, got {type(options).__name__}")
        try:
            return cls(options).card.vpp
        except (OSError, ValueError):
            card = cls.shipped()
            return card.vpp if card is not None else NETWORK_VPP

    def __init__(self, options: OnnxOptions | Mapping[str, object] | None = None) -> None:
        super().__init__(options)
        self.section = f"matcher.{self.name}"
        self.remote = self.options.engine == "triton"
        self.model_path = Path(self.options.model) if self.remote else self._model_path()
        self.card = self._card()
        if self.remote:
            self.model_path = Path(self.options.model or self.card.name)
            if not self.card.name and not self.options.model:
                raise ValueError(f"{self.section}.model: the model's name on the Triton server (the card has no name)")
        #: True when ``max_disparity`` was left to the network (0): a fixed-size network then takes
        #: its range at each image's width.
        self.network_range = self.options.max_disparity == 0
        if self.network_range:
            self.options = replace(self.options, max_disparity=self.card.max_disparity)
        self._engine: Engine | None = None
        #: Milliseconds of the last :meth:`compute`: ``pre``, ``network``, ``post``.
        self.last_timing: dict[str, float] = {}
        if not self.card.fixed and self.options.max_disparity > self.card.max_disparity:
            raise ValueError(self._range_error(self.options.max_disparity, self.card.max_disparity))

    @property
    def max_range(self) -> int | None:
        """The network's disparity range (its card's ``max_disparity``)."""
        return self.card.max_disparity

    def _range_error(self, asked: int, limit: float) -> str:
        who = self.card.name or self.model_path.name
        return (
            f"{self.section}.max_disparity: {asked} exceeds the disparity range of the network "
            f"({who}: {limit:g}); use max_disparity <= {math.floor(limit)}"
        )

    def _model_path(self) -> Path:
        o = self.options
        if o.model:
            return find_model(o.model, f"{self.section}.model")
        shipped = self.shipped()
        if shipped is None or not shipped.model_file:
            raise ValueError(f"{self.section}.model: required (the path of the .onnx file)")
        p = models_dir() / shipped.model_file
        if not p.is_file():
            raise FileNotFoundError(
                f"{self.section}: no model: {p} does not exist (models folder: ${MODELS_ENV} or the user cache); "
                f"pass model=PATH" + (f", or {shipped.howto}" if shipped.howto else "")
            )
        return p

    def _card(self) -> ModelCard:
        o = self.options
        shipped = base = self.shipped()
        if o.card_file:
            base = read_card(Path(o.card_file).expanduser(), shipped)
        elif self.remote:
            pass  # no local model: the shipped card, the card keys, or card_file
        else:
            beside = find_card(self.model_path)
            if beside is not None:
                base = read_card(beside, shipped)
        if base is None and not o.card and self.remote:
            raise ValueError(f"{self.section}.card: engine 'triton' needs the model's card: card_file or card keys")
        if base is None and not o.card:
            raise ValueError(
                f"{self.section}.card: no model card for {self.model_path.name}: write "
                f"{self.model_path.with_suffix('.toml').name} beside it, or give card_file or card keys "
                "(docs/deep-matchers.md)"
            )
        if o.card:
            return card_from_mapping(o.card, f"{self.section}.card", base)
        assert base is not None
        return base

    def engine(self) -> Engine:
        """The opened network (opened and checked against the card on first use).

        Raises
        ------
        ValueError
            The graph does not match the card (input names, channels, sizes, output), or cannot be loaded.
        EngineUnavailable
            The engine is not installed or cannot run on the device.
        """
        if self._engine is None:
            o = self.options
            if self.remote:
                self._engine = self._remote_engine()
                return self._engine
            assert o.engine != "triton"
            threads = resolve_threads(o.threads or None)
            eng = open_engine(
                self.model_path,
                o.device,
                o.engine,
                o.precision,
                threads,
                providers=o.providers,
                provider_options=o.provider_options,
            )
            self._check_graph(eng)
            self._engine = eng
        return self._engine

    def runtime(self) -> MatcherRuntime:
        """The engine, device, precision and threads that run the network (opens it on first use).

        The precision is what the engine runs, which may differ from ``precision``
        (OpenVINO runs f32 where the CPU has no bf16 unit; it logs a warning then).
        """
        eng = self.engine()
        return {"engine": eng.kind, "device": eng.device, "precision": eng.precision, "threads": eng.threads}

    def triton_settings(self) -> TritonSettings:
        """Where the network is served (``engine = "triton"``)."""
        o = self.options
        return TritonSettings(
            urls=o.urls,
            model=str(self.model_path),
            model_version=o.model_version,
            ssl=o.ssl,
            root_certificates=o.root_certificates,
            private_key=o.private_key,
            certificate_chain=o.certificate_chain,
            timeout_ms=float(o.timeout_ms),
            retry_s=float(o.retry_s),
        )

    def _remote_engine(self, *, probe: bool = False) -> TritonEngine:
        """The Triton engine, its metadata read (``probe``: every server checked now) and checked against the card.

        Raises
        ------
        ServerUnavailable
            ``probe`` and no server can be reached.
        RuntimeError
            No server answered within ``retry_s`` (not ``probe``), or a server lacks the model.
        ValueError
            The model's metadata disagrees with the card (one line per mismatch).
        """
        eng = open_triton(self.triton_settings())
        if probe:
            eng.probe()
        else:
            eng.ensure_metadata()
        lines = metadata_mismatches(eng, self.card, self.card.output)
        if lines:
            head = f"{self.section}: the served model and the card disagree:"
            raise ValueError("\n  ".join([head, *lines]))
        return eng

    def network_status(self) -> dict[str, Any] | None:
        """``engine = "triton"``: the engine's counters and each server's state (None before it opened, or local)."""
        return self._engine.status() if isinstance(self._engine, TritonEngine) else None

    def _check_graph(self, eng: Engine) -> None:
        """Raise ValueError naming the first mismatch between the card and the graph's inputs and outputs."""
        card, who = self.card, f"{self.section}: {self.model_path.name}"
        keys = ("concat_input",) if card.concat_input else ("left_input", "right_input")
        for key in keys:
            name = getattr(card, key)
            if name not in eng.inputs:
                raise ValueError(
                    f"{who}: card {key} {name!r} is not an input of the graph; its inputs: {sorted(eng.inputs)}"
                )
            shape = eng.inputs[name]
            if shape and len(shape) != 4:
                raise ValueError(f"{who}: input {name!r} has rank {len(shape)}, expected 4 (1 x C x H x W)")
            if shape and shape[1] is not None and shape[1] != card.input_channels:
                both = " (both images)" if card.concat_input else ""
                raise ValueError(
                    f"{who}: input {name!r} takes {shape[1]} channels; "
                    f"card colour {card.colour!r} gives {card.input_channels}{both}"
                )
            hw = tuple(shape[2:]) if shape else (None, None)
            if card.fixed and any(s is not None for s in hw) and hw != tuple(card.input_size):
                raise ValueError(
                    f"{who}: input {name!r} is {hw[0]} x {hw[1]}, card input_size is {list(card.input_size)}"
                )
            if not card.fixed and all(s is not None for s in hw):
                raise ValueError(f"{who}: input {name!r} has the fixed size {hw[0]} x {hw[1]}: set card input_size")
        missing = sorted(set(card.extra_inputs) - set(eng.inputs))
        if missing:
            raise ValueError(f"{who}: card extra_inputs {missing} are not inputs of the graph: {sorted(eng.inputs)}")
        extra = sorted(set(eng.inputs) - {*card.image_inputs, *card.extra_inputs})
        if extra:
            raise ValueError(f"{who}: the graph has inputs the card does not feed: {extra}")
        out = self.output_name(eng)
        shape = eng.outputs[out]
        if shape and len(shape) != len(card.output_layout):
            raise ValueError(f"{who}: output {out!r} has rank {len(shape)}, card output_layout {card.output_layout!r}")

    def output_name(self, eng: Engine) -> str:
        """The graph output read as the disparity (the card's, or the only one)."""
        who = f"{self.section}: {self.model_path.name}"
        if self.card.output:
            if self.card.output not in eng.outputs:
                raise ValueError(
                    f"{who}: card output {self.card.output!r} is not an output of the graph; "
                    f"its outputs: {sorted(eng.outputs)}"
                )
            return self.card.output
        if len(eng.outputs) != 1:
            raise ValueError(f"{who}: the graph has outputs {sorted(eng.outputs)}: name one in the card (output)")
        return next(iter(eng.outputs))

    def forward(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """The network's disparity of a checked pair (cropped back, finite, not yet limited to the range)."""
        eng = self.engine()
        t0 = time.perf_counter()
        tl, lay = to_tensor(left, self.card)
        tr, _ = to_tensor(right, self.card, lay)
        t1 = time.perf_counter()
        raw = eng.run(network_feeds(tl, tr, self.card), self.output_name(eng))
        t2 = time.perf_counter()
        try:
            disp = from_output(raw, self.card, lay, f"{self.section}: {self.model_path.name}")
        except ValueError:
            if isinstance(eng, TritonEngine):
                eng.bad_reply()  # a reply of the wrong shape: counted, never published
            raise
        t3 = time.perf_counter()
        self.last_timing = {"pre": (t1 - t0) * 1e3, "network": (t2 - t1) * 1e3, "post": (t3 - t2) * 1e3}
        return disp

    def check_width(self, width: int) -> None:
        """The base rule, and for a fixed-size network a ``max_disparity`` within its range at this width."""
        super().check_width(width)
        d = self.options.max_disparity
        if self.card.fixed and not self.network_range and d > self.card.range_at(width):
            raise DisparityRangeError(self._range_error(d, self.card.range_at(width)))

    def _compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray:
        d = self.options.max_disparity
        if self.card.fixed and self.network_range:
            d = max(1, math.floor(self.card.range_at(left.shape[1])))
        disp = self.forward(left, right)
        t0 = time.perf_counter()
        disp[~((disp >= 0) & (disp < d))] = np.nan
        self.last_timing["post"] += (time.perf_counter() - t0) * 1e3
        return disp

    def check(self) -> str:
        """Open the network, check it against the card, run it once on a small pair; a one-line summary.

        Raises
        ------
        ValueError
            Card and graph disagree, or the dry run fails or returns NaN / inf.
        EngineUnavailable
            The engine is missing.
        """
        if self.remote:
            self._engine = self._remote_engine(probe=True)
        eng = self.engine()
        c = self.card
        if c.fixed:
            h, w = c.input_size
        else:
            h, w = c.min_size or (max(2 * c.pad_multiple, 32),) * 2
        rng = np.random.default_rng(0)
        shape = (h, w, 3)
        left = rng.integers(0, 256, shape, dtype=np.uint8)
        right = np.ascontiguousarray(np.roll(left, -2, axis=1))
        check_pair(left, right)
        try:
            self.forward(left, right)
        except RuntimeError as exc:
            raise ValueError(f"{self.section}: dry run on a {h} x {w} pair failed: {exc}") from None
        who = self.model_path.name if not self.remote else f"{c.name or 'no name'} card"
        return f"{who} ({c.name or 'no name'}): {eng.describe()}, range {c.max_disparity}"

    @classmethod
    def check_files(cls, options: MatcherOptions, section: str) -> None:
        """``run --check``: build the matcher, check the card against the graph and run it once (one-line errors)."""
        if not isinstance(options, cls.Options):
            raise TypeError(f"{section}: options must be {cls.Options.__name__}, got {type(options).__name__}")
        cls(options).check()


def _bound(network: str) -> type[OnnxMatcher]:
    """The ``onnx`` matcher bound to the shipped card ``network`` (registered under that name)."""
    doc = f"The ``onnx`` matcher with the shipped card ``cards/{network}.toml``."
    return cast(
        "type[OnnxMatcher]",
        type(f"OnnxMatcher[{network}]", (OnnxMatcher,), {"name": network, "network": network, "__doc__": doc}),
    )


for _network in shipped_cards():
    MATCHERS.register(_network)(_bound(_network))


def builtin_cards() -> dict[str, ModelCard]:
    """The shipped cards by their ``model_file`` (``models list`` shows them for files without a card beside)."""
    cards = (shipped_card(n) for n in shipped_cards())
    return {c.model_file: c for c in cards if c.model_file}


__all__ = [
    "Layout",
    "OnnxMatcher",
    "OnnxOptions",
    "builtin_cards",
    "from_output",
    "network_feeds",
    "tensor_layout",
    "to_tensor",
]
