"""PSMNet in PyTorch, for one job: turn a checkpoint into the ONNX model + card the ``psmnet`` matcher runs.

``vpp-service models export psmnet --checkpoint PATH`` (extra ``[export]``:
torch, onnx). The architecture is PSMNet's stacked-hourglass network as the
2018 upstream code defines it (J.-R. Chang, github.com/JiaRenChang/PSMNet,
MIT licence, Copyright (c) 2018 Jia-Ren Chang): the same modules and parameter
names, so a checkpoint's ``state_dict`` loads strictly (less the ``module.``
prefix DataParallel added). Two changes keep the computation and make it
exportable: the cost volume is built by padding and stacking instead of
in-place slice writes, and the upsampling states ``align_corners=True``, the
behaviour of the 2018 ``F.upsample`` (``False`` costs accuracy).

Export: the TorchScript exporter, opset 17, inputs ``left`` / ``right``
(``1 x 3 x H x W``, H and W dynamic), output ``disparity`` (``1 x H x W``);
the card (the shipped ``vpp_service/matchers/cards/psmnet.toml``, with the
checkpoint named in ``provenance``) is written beside it.

torch is imported here at module level: import this module only where an
export is asked for.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from vpp_service.matchers.model_card import card_to_toml, shipped_card


def _convbn(cin: int, cout: int, k: int, stride: int, pad: int, *, dilation: int = 1) -> nn.Sequential:
    padding = dilation if dilation > 1 else pad
    return nn.Sequential(
        nn.Conv2d(cin, cout, kernel_size=k, stride=stride, padding=padding, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
    )


def _convbn_3d(cin: int, cout: int, k: int, stride: int, pad: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv3d(cin, cout, kernel_size=k, padding=pad, stride=stride, bias=False), nn.BatchNorm3d(cout)
    )


class _BasicBlock(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int, downsample: nn.Module | None, *, dilation: int) -> None:
        super().__init__()
        self.conv1 = nn.Sequential(_convbn(cin, cout, 3, stride, 1, dilation=dilation), nn.ReLU(inplace=True))
        self.conv2 = _convbn(cout, cout, 3, 1, 1, dilation=dilation)
        self.downsample = downsample

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.conv2(self.conv1(x))
        return out + (x if self.downsample is None else self.downsample(x))


def _up(x: torch.Tensor, size: Any, mode: str = "bilinear") -> torch.Tensor:
    return F.interpolate(x, size, mode=mode, align_corners=True)


class _FeatureExtraction(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.inplanes = 32
        relu = nn.ReLU
        self.firstconv = nn.Sequential(
            _convbn(3, 32, 3, 2, 1, dilation=1),
            relu(True),
            _convbn(32, 32, 3, 1, 1, dilation=1),
            relu(True),
            _convbn(32, 32, 3, 1, 1, dilation=1),
            relu(True),
        )
        self.layer1 = self._make_layer(32, 3, 1, 1)
        self.layer2 = self._make_layer(64, 16, 2, 1)
        self.layer3 = self._make_layer(128, 3, 1, 1)
        self.layer4 = self._make_layer(128, 3, 1, 2)
        for i, k in ((1, 64), (2, 32), (3, 16), (4, 8)):
            branch = nn.Sequential(
                nn.AvgPool2d((k, k), stride=(k, k)), _convbn(128, 32, 1, 1, 0, dilation=1), relu(True)
            )
            setattr(self, f"branch{i}", branch)
        self.lastconv = nn.Sequential(
            _convbn(320, 128, 3, 1, 1, dilation=1),
            relu(True),
            nn.Conv2d(128, 32, kernel_size=1, padding=0, stride=1, bias=False),
        )

    def _make_layer(self, planes: int, blocks: int, stride: int, dilation: int) -> nn.Sequential:
        downsample = None
        if stride != 1 or self.inplanes != planes:
            downsample = nn.Sequential(
                nn.Conv2d(self.inplanes, planes, kernel_size=1, stride=stride, bias=False), nn.BatchNorm2d(planes)
            )
        layers = [_BasicBlock(self.inplanes, planes, stride, downsample, dilation=dilation)]
        self.inplanes = planes
        layers += [_BasicBlock(planes, planes, 1, None, dilation=dilation) for _ in range(1, blocks)]
        return nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.layer1(self.firstconv(x))
        raw = self.layer2(out)
        skip = self.layer4(self.layer3(raw))
        size = (skip.size()[2], skip.size()[3])
        branches = [_up(getattr(self, f"branch{i}")(skip), size) for i in (4, 3, 2, 1)]
        return self.lastconv(torch.cat((raw, skip, *branches), 1))


class _Hourglass(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.conv1 = nn.Sequential(_convbn_3d(c, c * 2, 3, 2, 1), nn.ReLU(inplace=True))
        self.conv2 = _convbn_3d(c * 2, c * 2, 3, 1, 1)
        self.conv3 = nn.Sequential(_convbn_3d(c * 2, c * 2, 3, 2, 1), nn.ReLU(inplace=True))
        self.conv4 = nn.Sequential(_convbn_3d(c * 2, c * 2, 3, 1, 1), nn.ReLU(inplace=True))
        self.conv5 = nn.Sequential(
            nn.ConvTranspose3d(c * 2, c * 2, 3, padding=1, output_padding=1, stride=2, bias=False),
            nn.BatchNorm3d(c * 2),
        )
        self.conv6 = nn.Sequential(
            nn.ConvTranspose3d(c * 2, c, 3, padding=1, output_padding=1, stride=2, bias=False), nn.BatchNorm3d(c)
        )

    def forward(
        self, x: torch.Tensor, presqu: torch.Tensor | None, postsqu: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        out = self.conv1(x)
        pre = self.conv2(out)
        pre = F.relu(pre + postsqu) if postsqu is not None else F.relu(pre)
        out = self.conv4(self.conv3(pre))
        post = F.relu(self.conv5(out) + (presqu if presqu is not None else pre))
        return self.conv6(post), pre, post


def _classifier() -> nn.Sequential:
    return nn.Sequential(
        _convbn_3d(32, 32, 3, 1, 1), nn.ReLU(inplace=True), nn.Conv3d(32, 1, kernel_size=3, padding=1, bias=False)
    )


class PSMNetModel(nn.Module):
    """PSMNet (stacked hourglass) in inference form: ``forward(left, right) -> 1 x H x W`` disparity.

    Parameters
    ----------
    maxdisp : int
        Disparity range (192 for the published checkpoints; a multiple of 4).
    """

    def __init__(self, maxdisp: int = 192) -> None:
        super().__init__()
        self.maxdisp = maxdisp
        self.feature_extraction = _FeatureExtraction()
        self.dres0 = nn.Sequential(
            _convbn_3d(64, 32, 3, 1, 1), nn.ReLU(inplace=True), _convbn_3d(32, 32, 3, 1, 1), nn.ReLU(inplace=True)
        )
        self.dres1 = nn.Sequential(_convbn_3d(32, 32, 3, 1, 1), nn.ReLU(inplace=True), _convbn_3d(32, 32, 3, 1, 1))
        self.dres2 = _Hourglass(32)
        self.dres3 = _Hourglass(32)
        self.dres4 = _Hourglass(32)
        self.classif1 = _classifier()
        self.classif2 = _classifier()
        self.classif3 = _classifier()

    def cost_volume(self, ref: torch.Tensor, tgt: torch.Tensor) -> torch.Tensor:
        """``B x 2C x D/4 x H x W``: left features and right ones shifted by ``i``, zero where ``x < i``."""
        levels = []
        for i in range(self.maxdisp // 4):
            if i == 0:
                levels.append(torch.cat((ref, tgt), 1))
            else:
                r = F.pad(ref[:, :, :, i:], (i, 0, 0, 0))
                t = F.pad(tgt[:, :, :, :-i], (i, 0, 0, 0))
                levels.append(torch.cat((r, t), 1))
        return torch.stack(levels, 2)

    def forward(self, left: torch.Tensor, right: torch.Tensor) -> torch.Tensor:
        """Disparity of the left view, ``B x H x W`` (soft-argmin over ``maxdisp``)."""
        cost = self.cost_volume(self.feature_extraction(left), self.feature_extraction(right))
        cost0 = self.dres0(cost)
        cost0 = self.dres1(cost0) + cost0
        out1, pre1, post1 = self.dres2(cost0, None, None)
        out1 = out1 + cost0
        out2, _, post2 = self.dres3(out1, pre1, post1)
        out2 = out2 + cost0
        out3, _, _ = self.dres4(out2, pre1, post2)
        out3 = out3 + cost0
        cost1 = self.classif1(out1)
        cost2 = self.classif2(out2) + cost1
        cost3 = self.classif3(out3) + cost2
        cost3 = _up(cost3, (self.maxdisp, left.size()[2], left.size()[3]), mode="trilinear")
        prob = F.softmax(torch.squeeze(cost3, 1), dim=1)
        values = torch.arange(self.maxdisp, dtype=prob.dtype).reshape(1, self.maxdisp, 1, 1)
        return torch.sum(prob * values, 1)


def load_checkpoint(model: PSMNetModel, path: str | Path) -> None:
    """Load a PSMNet checkpoint (``{"state_dict": ...}`` or a bare state dict) strictly, ``module.`` stripped.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a PSMNet checkpoint (missing or unexpected keys, wrong shapes); one line.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(f"--checkpoint: no such file: {p}")
    try:
        data = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - pickle, zip and torch errors: one line naming the file
        raise ValueError(f"--checkpoint {p.name}: not a torch checkpoint: {str(exc).splitlines()[0]}") from None
    state = data.get("state_dict", data) if isinstance(data, dict) else None
    if not isinstance(state, dict):
        raise ValueError(f"--checkpoint {p.name}: no state_dict in it")
    state = {k.removeprefix("module."): v for k, v in state.items()}
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        raise ValueError(f"--checkpoint {p.name}: not PSMNet's stacked hourglass: {str(exc).splitlines()[0]}") from None


def export_onnx(model: PSMNetModel, out: str | Path, height: int = 384, width: int = 1248) -> Path:
    """Export ``model`` (eval mode) to ONNX at ``out`` (dynamic H, W; traced at ``height x width``)."""
    model.eval()
    x = torch.zeros(1, 3, height, width)
    out = Path(out)
    with torch.no_grad():
        torch.onnx.export(
            model,
            (x, x),
            str(out),
            opset_version=17,
            input_names=["left", "right"],
            output_names=["disparity"],
            dynamic_axes={"left": {2: "H", 3: "W"}, "right": {2: "H", 3: "W"}, "disparity": {1: "H", 2: "W"}},
            dynamo=False,
        )
    return out


def export_psmnet(
    checkpoint: str | Path | None,
    out: str | Path,
    *,
    seed: int = 0,
    state: dict[str, torch.Tensor] | None = None,
    height: int = 384,
    width: int = 1248,
) -> tuple[Path, Path]:
    """Checkpoint -> ``out`` (.onnx) + its card (.toml beside).

    Parameters
    ----------
    checkpoint : path or None
        The checkpoint file; None: ``state`` if given, else random weights (``seed``; for tests).
    out : path
        The ``.onnx`` to write (its folder must exist).
    state : dict or None
        A state dict to load instead of a file (strict).
    height, width : int
        Size the graph is traced at (the exported graph takes any multiple of 16, at least 256).

    Returns
    -------
    (Path, Path)
        The model and the card written.
    """
    torch.manual_seed(seed)
    shipped = shipped_card("psmnet")
    model = PSMNetModel(shipped.max_disparity)
    provenance = f"randomly initialised (seed {seed}): for tests only"
    if state is not None:
        model.load_state_dict(state, strict=True)
        provenance = "PSMNet stackhourglass from a state dict given in Python, ONNX opset 17"
    if checkpoint is not None:
        load_checkpoint(model, checkpoint)
        digest = hashlib.sha256(Path(checkpoint).expanduser().read_bytes()).hexdigest()
        provenance = (
            f"PSMNet stackhourglass from {Path(checkpoint).name} (sha256 {digest[:16]}), exported by "
            "vpp-service models export, ONNX opset 17"
        )
    path = export_onnx(model, out, height, width)
    card = replace(shipped, name=path.stem, provenance=provenance, model_file="", howto="")
    card_file = path.with_suffix(".toml")
    card_file.write_text(card_to_toml(card))
    return path, card_file


__all__ = ["PSMNetModel", "export_onnx", "export_psmnet", "load_checkpoint"]
