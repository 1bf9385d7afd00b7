"""The matcher interface and its registry (the input contract: :mod:`~vpp_service.matchers.inputs`).

A matcher turns a rectified pair into a dense disparity map of the left view:

>>> from vpp_service.matchers import build_matcher
>>> m = build_matcher("sgbm", {"max_disparity": 64})  # doctest: +SKIP
>>> disp = m.compute(left, right)  # doctest: +SKIP

Conventions (all matchers)
--------------------------
* ``left``/``right``: C-contiguous uint8 arrays, H x W or H x W x C with
  C = 1 or 3 (RGB), the same shape.
* Output: H x W float32 disparity of the left view (``x_right = x - d``),
  NaN = invalid. ``options.fill`` fills the NaN holes with
  :func:`~vpp_service.matchers.holes.fill_holes` before returning.
* ``max_disparity`` is the number of disparity hypotheses ``D``: the search
  range is ``0 .. D - 1`` and ``D`` must be smaller than the image width.
* Guided stereo: matchers with ``supports_guidance`` accept ``hints``, an
  H x W float32 sparse disparity map (NaN or <= 0 = no hint).
* Confidence: :meth:`Matcher.compute_with_confidence` also returns an H x W
  float32 confidence in ``[0, 1]`` (0 where there is no answer), see
  :mod:`~vpp_service.matchers.confidence`; ``options.min_confidence`` turns the
  pixels below it into holes in every call.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, ClassVar, TypedDict

import numpy as np

from vpp_service.matchers.confidence import apply_min_confidence, lr_confidence, right_view
from vpp_service.matchers.holes import fill_holes
from vpp_service.matchers.inputs import check_hints, check_pair
from vpp_service.registry import Registry
from vpp_service.settings import Options, Range, from_mapping

#: Registered matcher classes by name ("sgbm", "bm", "census-sgm", "onnx", "psmnet").
MATCHERS: Registry[Matcher] = Registry("matcher")


@dataclass(frozen=True)
class MatcherOptions(Options):
    """Options common to every matcher.

    Attributes
    ----------
    max_disparity : int
        Number of disparity hypotheses D (search range ``0 .. D-1``), > 0 and
        smaller than the image width (checked at ``compute``). OpenCV matchers
        round it up to a multiple of 16. Default 128.
    fill : bool
        Fill invalid pixels with background interpolation
        (:func:`~vpp_service.matchers.holes.fill_holes`). Default False.
    min_confidence : float
        Pixels whose confidence (:meth:`Matcher.compute_with_confidence`) is below
        this become holes (NaN), before ``fill``; in [0, 1], 0 (default) = off. Any
        value above 0 makes every call compute the confidence (for matchers other
        than census-sgm, a second matching pass).
    """

    max_disparity: Annotated[int, Range(1, 4096)] = 128
    fill: bool = False
    min_confidence: Annotated[float, Range(0.0, 1.0)] = 0.0


class DisparityRangeError(ValueError):
    """The matcher's disparity range cannot fit an image this wide (``max_disparity`` not below the width).

    Not a flaw of one frame: every frame of that width fails the same way, so the
    service stops on it (a configuration that cannot process the source's frames)
    instead of rejecting frame after frame.
    """


def check_max_disparity(max_disparity: int, width: int, name: str = "max_disparity") -> None:
    """Raise :class:`DisparityRangeError` (a ValueError) unless ``0 < max_disparity < width``."""
    if isinstance(max_disparity, bool) or not isinstance(max_disparity, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {max_disparity!r}")
    if not 0 < max_disparity < width:
        raise DisparityRangeError(f"{name} must be > 0 and < the image width {width}, got {max_disparity}")


class MatcherRuntime(TypedDict):
    """What actually runs a matcher (``run``'s start line, ``@status``, ``eval``'s results).

    Attributes
    ----------
    engine : str
        The implementation: ``"opencv"``, ``"cython"`` / ``"cython-avx2"`` (the build
        of the kernels that runs), ``"openvino"``, ``"onnxruntime"``.
    device : str
        ``"cpu"`` or ``"cuda"``.
    precision : str
        The arithmetic that runs, as the engine reports it: ``"f32"``, ``"bf16"``,
        ``"f16"`` for a network (what it runs, not what was asked), ``"int16"``
        for the classical matchers' integer costs.
    threads : int
        CPU threads it uses.
    """

    engine: str
    device: str
    precision: str
    threads: int


class Matcher(ABC):
    """Base class of stereo matchers.

    Subclasses define ``Options`` (a frozen dataclass deriving from
    :class:`MatcherOptions`), ``name``, optionally ``supports_guidance``, and
    implement :meth:`_compute`.

    Parameters
    ----------
    options : Options, Mapping or None
        An ``Options`` instance, a mapping validated with
        :func:`vpp_service.settings.from_mapping`, or None for the defaults.
    """

    #: Registered name.
    name: ClassVar[str] = ""
    #: Frozen dataclass of options.
    Options: ClassVar[type[MatcherOptions]] = MatcherOptions
    #: True when :meth:`compute` accepts ``hints`` (guided stereo).
    supports_guidance: ClassVar[bool] = False

    @classmethod
    def preferred_vpp(cls, options: MatcherOptions | Mapping[str, object] | None = None) -> Mapping[str, object]:
        """:class:`~vpp_service.vpp.VPPConfig` fields that suit this matcher better than VPP's own defaults.

        ``eval`` and the service apply them where the user set nothing. A
        network's come from its card (``[vpp]``, its measured best); the
        classic matchers have none (VPP's defaults).
        """
        return {}

    #: The validated options (an instance of ``Options``).
    options: MatcherOptions

    @property
    def max_range(self) -> int | None:
        """The largest ``max_disparity`` this matcher can search (None: only the image width limits it).

        A network with a fixed cost-volume depth has one; ``max_disparity = "auto"``
        and ``eval``'s per-scene default are capped at it.
        """
        return None

    def check_width(self, width: int) -> None:
        """Raise :class:`DisparityRangeError` when the range cannot be searched on images ``width`` pixels wide.

        :meth:`compute` runs it on every pair; ``run --check`` runs it on the
        source's frame width when the source knows it in advance. The base
        rule is ``0 < max_disparity < width``; matchers with a stricter one
        (OpenCV's rounding to 16) override it.
        """
        check_max_disparity(self.options.max_disparity, width)

    def runtime(self) -> MatcherRuntime:
        """The engine, device and precision that run this matcher (:class:`MatcherRuntime`).

        The base class's answer is numpy on the CPU in f32, one thread; every
        registered matcher overrides it. A network's opens its engine first.
        """
        return {"engine": "numpy", "device": "cpu", "precision": "f32", "threads": 1}

    def warm_up(self, left: np.ndarray, right: np.ndarray) -> None:
        """One untimed :meth:`compute` on a pair of this size, so that the timings that follow are steady.

        A network's engine opens and compiles for the size on its first pair
        (seconds); kernels allocate their buffers. ``eval`` and ``demo`` run it
        before they time any method.
        """
        self.compute(left, right)

    @classmethod  # noqa: B027 - optional hook, a no-op by default
    def check_files(cls, options: MatcherOptions, section: str) -> None:
        """Check what the options name on disk and load (``run --check``, before the service starts); nothing here.

        Matchers that load a model override it (open it, check it, run it once).

        Raises
        ------
        OSError, ValueError
            A named file is missing or unusable; one line naming ``section``.
        """

    def __init__(self, options: MatcherOptions | Mapping[str, object] | None = None) -> None:
        if options is None or isinstance(options, Mapping):
            options = from_mapping(self.Options, options, f"matcher.{self.name}")
        elif not isinstance(options, self.Options):
            raise TypeError(
                f"options must be a {self.Options.__name__}, a mapping or None, got {type(options).__name__}"
            )
        self.options = options

    def compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None = None) -> np.ndarray:
        """Dense disparity of the left view.

        Parameters
        ----------
        left, right : ndarray
            Rectified pair, C-contiguous uint8, H x W or H x W x C (C = 1 | 3, RGB).
        hints : ndarray or None
            H x W float sparse disparity (NaN or <= 0 = none); only for
            matchers with ``supports_guidance``.

        Returns
        -------
        ndarray
            H x W float32 disparity, NaN = invalid (no NaN when ``fill``,
            except on rows without any valid pixel).

        Raises
        ------
        TypeError, ValueError
            Bad images (dtype, shape, contiguity), ``max_disparity`` not below
            the width (:class:`DisparityRangeError`, :meth:`check_width`), or
            ``hints`` given to a matcher without guidance.
        """
        if self.options.min_confidence > 0:
            return self.compute_with_confidence(left, right, hints)[0]
        hints = self._check_inputs(left, right, hints)
        disp = self._compute(left, right, hints)
        if self.options.fill:
            disp = fill_holes(disp)
        return disp

    def compute_with_confidence(
        self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Dense disparity of the left view and its per-pixel confidence.

        Parameters are those of :meth:`compute`. The confidence is census-SGM's own
        (one pass) or, for every other matcher, the left-right agreement of a second
        pass on the mirrored pair (:mod:`~vpp_service.matchers.confidence`). Pixels
        below ``options.min_confidence`` become holes; then ``fill`` runs.

        Returns
        -------
        disparity : ndarray
            H x W float32, as :meth:`compute` returns it.
        confidence : ndarray
            H x W float32 in [0, 1]; 0 wherever the matcher gave no answer (its holes,
            and with ``fill`` the pixels the filling interpolated).

        Raises
        ------
        TypeError, ValueError
            As :meth:`compute`.
        """
        hints = self._check_inputs(left, right, hints)
        disp, conf = self._compute_confidence(left, right, hints)
        disp = apply_min_confidence(np.asarray(disp, dtype=np.float32), conf, self.options.min_confidence)
        if self.options.fill:
            disp = fill_holes(disp)
        return disp, conf

    def _check_inputs(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray | None:
        """Validate the pair, the width and the hints (returned checked) for :meth:`compute`."""
        check_pair(left, right)
        self.check_width(left.shape[1])
        if hints is not None:
            if not self.supports_guidance:
                raise ValueError(f"matcher {self.name!r} does not support guidance (hints)")
            hints = check_hints(hints, left.shape[:2])
        return hints

    def _compute_confidence(
        self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The disparity and its confidence on validated inputs (a new, writeable float32 map).

        The default: :meth:`_compute`, then the right view's disparity from a second
        pass on the mirrored pair (no hints: they belong to the left view) and the
        left-right agreement (:func:`~vpp_service.matchers.confidence.lr_confidence`).
        Matchers with a cheaper confidence of their own override it.
        """
        disp = np.asarray(self._compute(left, right, hints), dtype=np.float32)
        disp_right = right_view(lambda a, b: self._compute(a, b, None), left, right)
        return disp, lr_confidence(disp, disp_right)

    @abstractmethod
    def _compute(self, left: np.ndarray, right: np.ndarray, hints: np.ndarray | None) -> np.ndarray:
        """Matcher-specific work on validated inputs; returns H x W float32, NaN = invalid."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.options!r})"


def build_matcher(name: str, options: Mapping[str, object] | None = None) -> Matcher:
    """Build the matcher registered as ``name`` from a plain options mapping.

    Raises
    ------
    ValueError
        Unknown matcher name (lists the known ones).
    vpp_service.settings.SettingsError
        Unknown option key or bad value (a ValueError naming ``matcher.<name>.<key>``).
    """
    cls = MATCHERS.get(name)
    return cls(from_mapping(cls.Options, options, f"matcher.{name}"))
