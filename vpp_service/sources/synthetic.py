"""Synthetic stereo scenes with exact ground truth: textured planes and boxes.

A scene is a background plane plus a few rectangular surfaces in front of it.
A plane in space has an *affine* disparity in a rectified pair, so every
surface ``s`` is described in left-image coordinates by
``d_s(x, y) = a_s x + b_s y + c_s`` over a rectangular support. Its texture
``T_s`` is a smooth random image attached to the surface, indexed by the left
coordinates of the surface point.

Rendering samples the texture in surface coordinates, so both views are exact
and consistent:

* left pixel ``(x, y)``: every surface covering it is a candidate, the largest
  disparity (nearest) wins (z-buffer); colour ``T_s(x, y)``;
* right pixel ``(x', y)``: the surface point seen there has left coordinate
  ``x_s = (x' + b_s y + c_s) / (1 - a_s)``; surfaces whose support holds
  ``x_s`` compete by disparity ``d_s(x_s, y)``; colour ``T_s(x_s, y)``.

Occlusions are therefore physically right. A left pixel is *non-occluded*
(``nocc_mask``) when its match ``x - d`` lies inside the right image and the
right view's winning surface there is the same one. The ground truth is
defined everywhere (the background covers the image), so it has no NaN.

``kind="planes"`` gives slanted rectangles, ``kind="boxes"`` fronto-parallel
ones (constant disparity). ``texture="weak"`` gives every surface a
low-contrast texture (std of about ``weak_contrast`` grey levels), the regime
where stereo matching fails and sparse depth helps most.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vpp_service.frame import Calibration, StereoFrame


@dataclass
class _Surface:
    a: float
    b: float
    c: float
    x0: float
    x1: float
    y0: float
    y1: float
    texture: np.ndarray  # H x (W + pad) x 3 float32, column j <-> left x = j - pad


def _texture(rng: np.random.Generator, h: int, w: int, contrast: float) -> np.ndarray:
    """Smooth random RGB texture, H x W x 3 float32 around a random base colour."""
    small = rng.standard_normal((max(h // 3, 2), max(w // 3, 2))).astype(np.float32)
    tex = np.asarray(cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC), dtype=np.float32)
    tex *= contrast / max(float(tex.std()), 1e-6)
    base = rng.uniform(60, 190, size=3).astype(np.float32)
    tint = rng.uniform(0.7, 1.0, size=3).astype(np.float32)
    return np.clip(base[None, None, :] + tex[..., None] * tint[None, None, :], 0, 255).astype(np.float32)


def _check_int(name: str, v: int, lo: int) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name}: must be an integer >= {lo}, got {v!r}")


def _layout(
    rng: np.random.Generator, kind: str, n_objects: int, *, h: int, w: int, dmax: float, pad: int, contrast: float
) -> list[_Surface]:
    """The slanted background plane, then ``n_objects`` random rectangles (drawn from ``rng`` in that order)."""

    def tex() -> np.ndarray:
        return _texture(rng, h, w + 2 * pad, contrast)

    # background: slanted (nearer at the bottom, like a floor/wall mix)
    lo, hi = 0.15 * dmax, 0.4 * dmax
    bb = rng.uniform(0.3, 1.0) * (hi - lo) / h
    ba = rng.uniform(-0.3, 0.3) * (hi - lo) / w
    bc = lo + (hi - lo) * 0.1 - min(ba * (w - 1), 0.0)
    surfaces = [_Surface(ba, bb, bc, -np.inf, np.inf, -np.inf, np.inf, tex())]
    for _ in range(n_objects):
        sw, sh = rng.uniform(0.2, 0.45) * w, rng.uniform(0.2, 0.5) * h
        x0, y0 = rng.uniform(0, w - sw), rng.uniform(0, h - sh)
        dc = rng.uniform(0.5, 0.95) * dmax
        if kind == "planes":
            room = min(dc - 0.45 * dmax, dmax - dc)
            a = rng.uniform(-1, 1) * room / sw
            b = rng.uniform(-1, 1) * (room - abs(a) * sw / 2) / (sh / 2) / 2
            a = float(np.clip(a, -0.25, 0.25))
        else:
            a = b = 0.0
        xc, yc = x0 + sw / 2, y0 + sh / 2
        c = dc - a * xc - b * yc
        surfaces.append(_Surface(a, b, c, x0, x0 + sw, y0, y0 + sh, tex()))
    return surfaces


def _render(
    surfaces: list[_Surface], xs: np.ndarray, ys: np.ndarray, *, pad: int, right: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One view by z-buffer: the image (float32 RGB), the winning disparity and the winning surface index."""
    h, w = xs.shape
    best = np.full((h, w), -np.inf, np.float32)
    owner = np.zeros((h, w), np.int16)
    coords = []
    for i, s in enumerate(surfaces):
        xs_s = (xs + s.b * ys + s.c) / (1.0 - s.a) if right else xs
        d = s.a * xs_s + s.b * ys + s.c
        inside = (xs_s >= s.x0) & (xs_s < s.x1) & (ys >= s.y0) & (ys < s.y1)
        win = inside & (d > best)
        best[win] = d[win]
        owner[win] = i
        coords.append(xs_s)
    img = np.zeros((h, w, 3), np.float32)
    for i, s in enumerate(surfaces):
        sel = owner == i
        if not sel.any():
            continue
        sampled = cv2.remap(
            s.texture, (coords[i] + pad).astype(np.float32), ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT
        )
        img[sel] = sampled[sel]
    return img, best, owner


def _visible_in_right(
    surfaces: list[_Surface], xs: np.ndarray, ys: np.ndarray, gt: np.ndarray, owner_l: np.ndarray
) -> np.ndarray:
    """Non-occlusion mask of the left view: the match is inside the right image and no other surface hides it."""
    xr = xs - gt
    nocc = xr >= -0.5
    for i, s in enumerate(surfaces):
        xt = (xr + s.b * ys + s.c) / (1.0 - s.a)
        dt = s.a * xt + s.b * ys + s.c
        inside = (xt >= s.x0) & (xt < s.x1) & (ys >= s.y0) & (ys < s.y1)
        nocc &= ~(inside & (owner_l != i) & (dt > gt + 1e-3))
    return nocc


def make_scene(
    height: int = 240,
    width: int = 320,
    *,
    seed: int = 0,
    kind: str = "planes",
    max_disparity: float = 48,
    texture: str = "random",
    n_objects: int = 4,
    f: float = 500.0,
    baseline: float = 0.1,
    noise: float = 0.0,
    weak_contrast: float = 2.0,
) -> StereoFrame:
    """Render a synthetic rectified stereo pair with exact ground truth.

    Parameters
    ----------
    height, width : int
        Image size (>= 16 each).
    seed : int
        Seed of the layout, the textures and the noise (>= 0).
    kind : {"planes", "boxes"}
        Slanted rectangles or fronto-parallel ones in front of a slanted background.
    max_disparity : float
        Largest disparity in the scene (px, >= 4, < width / 2).
    texture : {"random", "weak"}
        Well-textured surfaces (std about 40 grey levels) or low-texture ones.
    n_objects : int
        Number of foreground rectangles (>= 0).
    f, baseline : float
        Nominal calibration stored in the frame (px, metres).
    noise : float
        Std of independent Gaussian image noise added to each view (grey levels).
    weak_contrast : float
        Texture std (grey levels) used with ``texture="weak"``.

    Returns
    -------
    StereoFrame
        ``left``/``right`` uint8 RGB, ``gt_disparity`` float32 (left view),
        ``nocc_mask`` bool, ``calib`` (``f``, ``baseline``, centred principal
        point), ``name`` ``"synthetic-<kind>-<seed>"``, ``meta["dataset"] = "synthetic"``.
    """
    _check_int("height", height, 16)
    _check_int("width", width, 16)
    _check_int("seed", seed, 0)
    _check_int("n_objects", n_objects, 0)
    if kind not in ("planes", "boxes"):
        raise ValueError(f"kind: must be 'planes' or 'boxes', got {kind!r}")
    if texture not in ("random", "weak"):
        raise ValueError(f"texture: must be 'random' or 'weak', got {texture!r}")
    if (
        isinstance(max_disparity, bool)
        or not isinstance(max_disparity, (int, float))
        or not np.isfinite(max_disparity)
        or not 4 <= max_disparity < width / 2
    ):
        raise ValueError(f"max_disparity: must be in [4, width/2), got {max_disparity!r}")
    for name, v, lo in (("noise", noise, 0.0), ("weak_contrast", weak_contrast, 0.0)):
        if not np.isfinite(v) or v < lo:
            raise ValueError(f"{name}: must be a finite number >= {lo}, got {v!r}")
    calib = Calibration(f=float(f), baseline=float(baseline), cx=(width - 1) / 2.0, cy=(height - 1) / 2.0)

    rng = np.random.default_rng(seed)
    h, w, dmax = int(height), int(width), float(max_disparity)
    pad = int(np.ceil(dmax)) + 8
    contrast = 40.0 if texture == "random" else float(weak_contrast)
    surfaces = _layout(rng, kind, n_objects, h=h, w=w, dmax=dmax, pad=pad, contrast=contrast)

    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    left_f, gt, owner_l = _render(surfaces, xs, ys, pad=pad, right=False)
    right_f, _, _ = _render(surfaces, xs, ys, pad=pad, right=True)
    nocc = _visible_in_right(surfaces, xs, ys, gt, owner_l)

    if noise > 0:
        left_f = left_f + rng.normal(0.0, noise, left_f.shape).astype(np.float32)
        right_f = right_f + rng.normal(0.0, noise, right_f.shape).astype(np.float32)
    left = np.clip(np.rint(left_f), 0, 255).astype(np.uint8)
    right = np.clip(np.rint(right_f), 0, 255).astype(np.uint8)
    return StereoFrame(
        left=left,
        right=right,
        calib=calib,
        gt_disparity=gt.astype(np.float32),
        nocc_mask=nocc,
        name=f"synthetic-{kind}-{seed}",
        meta={"dataset": "synthetic", "kind": kind, "texture": texture, "seed": seed, "max_disparity": dmax},
    )


__all__ = ["make_scene"]
