"""Wire format v1: round trips, the documented example, and rejection of malformed messages."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import msgpack
import numpy as np
import pytest

from helpers import hostile
from helpers.frames import make_frame
from vpp_service.frame import Calibration, FusionResult, StereoFrame
from vpp_service.transport import wire
from vpp_service.transport.wire import WireError
from vpp_service.vpp import depth_to_disparity


def raw_msg(**changes):
    msg = msgpack.unpackb(wire.encode_frame(make_frame()), raw=False)
    for k, v in changes.items():
        if v is KeyError:
            msg.pop(k)
        else:
            msg[k] = v
    return msgpack.packb(msg, use_bin_type=True)


def test_a_raw_frame_needs_no_calib_and_a_rectified_one_says_so():
    raw = make_frame().with_(calib=None)
    out = wire.decode_frame(wire.encode_frame(raw))
    assert out.calib is None and "rectified" not in out.meta
    assert "calib" not in msgpack.unpackb(wire.encode_frame(raw), raw=False)
    marked = make_frame().with_(meta={"rectified": True})
    out = wire.decode_frame(wire.encode_frame(marked))
    assert out.meta["rectified"] is True and out.calib == marked.calib
    left = wire.decode_part(wire.encode_part(marked.with_(calib=None), "left"), "left")
    right = wire.decode_part(wire.encode_part(marked, "right"), "right")
    joined = wire.assemble(left, right, None)
    assert joined.calib is None and joined.meta["rectified"] is True


@pytest.mark.parametrize("c", [1, 3])
@pytest.mark.parametrize("enc", ["raw", "png"])
def test_frame_roundtrip_metric(c, enc):
    fr = make_frame(c=c)
    out = wire.decode_frame(wire.encode_frame(fr, enc=enc))
    np.testing.assert_array_equal(out.left, fr.left)
    np.testing.assert_array_equal(out.right, fr.right)
    assert (out.rig, out.seq, out.stamp_ns) == ("r1", 7, 123456789)
    assert out.calib == fr.calib
    np.testing.assert_array_equal(out.sensor_depth, fr.sensor_depth)  # NaN positions equal too
    # metric points also give their disparity, computed at the points: the reference is the dense conversion
    c_ = fr.calib
    np.testing.assert_array_equal(
        out.sparse_disparity, depth_to_disparity(out.sensor_depth, c_.f, c_.baseline, c_.doffs)
    )
    np.testing.assert_array_equal(out.gt_disparity, fr.gt_disparity)


@pytest.mark.parametrize("doffs", [0.0, 3.0, 40.0])
def test_points_disparity_equals_dense_conversion(doffs):
    """Colliding points (nearest wins), points whose disparity is <= 0 (large doffs)."""
    rng = np.random.default_rng(3)
    h, w = 12, 20
    n = 150  # more points than pixels: many collisions
    uv = np.stack([rng.uniform(-0.49, w - 0.51, n), rng.uniform(-0.49, h - 0.51, n)], 1).astype("<f4")
    z = rng.uniform(0.5, 30.0, n).astype("<f4")
    m = {"kind": "points", "n": n, "uv": uv.tobytes(), "z": z.tobytes()}
    calib = Calibration(f=100.0, baseline=0.5, doffs=doffs)
    sensor, disp = wire.decode_depth(m, h, w, calib=calib)
    ref = depth_to_disparity(sensor, calib.f, calib.baseline, calib.doffs)
    np.testing.assert_array_equal(disp, ref)
    assert np.isnan(disp).any() and np.isfinite(disp).any()
    assert wire.decode_depth(m, h, w)[1] is None  # no calibration: metric only
    alone = wire.decode_depth(m, h, w, calib=calib, metric_map=False)  # the disparity map alone, the same
    assert alone[0] is None
    np.testing.assert_array_equal(alone[1], ref)
    z, d = wire.decode_depth(m, h, w, metric_map=False)  # without a calibration the metric map stays
    np.testing.assert_array_equal(z, sensor)
    assert d is None


@pytest.mark.parametrize("kind", ["auto", "disparity_points", "map"])
@pytest.mark.parametrize("depth", ["metric", "disparity"])
def test_frame_without_metric_map(depth, kind):
    """decode_frame(metric_map=False): metric points as their disparity alone; anything else as by default."""
    fr = make_frame(depth=depth)
    payload = wire.encode_frame(fr, depth_kind=kind)
    full, alone = wire.decode_frame(payload), wire.decode_frame(payload, metric_map=False)
    np.testing.assert_array_equal(alone.left, full.left)
    if depth == "metric" and kind == "auto":  # metric points: no metric map, the same disparity map
        assert full.sensor_depth is not None and alone.sensor_depth is None
        np.testing.assert_array_equal(alone.sparse_disparity, full.sparse_disparity)
    else:  # a metric map (converted later) or disparity: unchanged
        for a, b in ((alone.sensor_depth, full.sensor_depth), (alone.sparse_disparity, full.sparse_disparity)):
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", ["auto", "disparity_points", "map"])
def test_frame_roundtrip_disparity(kind):
    fr = make_frame(depth="disparity")
    out = wire.decode_frame(wire.encode_frame(fr, depth_kind=kind))
    np.testing.assert_array_equal(out.sparse_disparity, fr.sparse_disparity)
    assert out.sensor_depth is None


def test_jpeg_roundtrip_is_close():
    fr = make_frame(h=32, w=48)
    out = wire.decode_frame(wire.encode_frame(fr, enc="jpeg"))
    assert out.left.shape == fr.left.shape
    assert np.abs(out.left.astype(int) - fr.left.astype(int)).mean() < 60


def test_no_depth_no_gt():
    fr = make_frame().with_(sensor_depth=None, gt_disparity=None)
    out = wire.decode_frame(wire.encode_frame(fr))
    assert out.sensor_depth is None and out.sparse_disparity is None and out.gt_disparity is None


def test_collision_keeps_nearest():
    uv = np.array([[2.2, 1.0], [1.8, 1.0]], "<f4")
    m = {"kind": "points", "n": 2, "uv": uv.tobytes(), "z": np.array([3.0, 1.0], "<f4").tobytes()}
    z, d = wire.decode_depth(m, 4, 4)
    assert d is None and z[1, 2] == 1.0 and np.isfinite(z).sum() == 1
    m = {"kind": "disparity_points", "n": 2, "uv": uv.tobytes(), "d": np.array([3.0, 1.0], "<f4").tobytes()}
    z, d = wire.decode_depth(m, 4, 4)
    assert z is None and d[1, 2] == 3.0


#: The worked example of docs/wire-format.md (2x3 gray frame, one metric depth point).
DOC_EXAMPLE_HEX = (
    "88a17601a3726967a172a373657101a87374616d705f6e7302a46c65667486a16802a17703a16301a56474797065a27538"
    "a3656e63a3726177a464617461c406000102030405a5726967687486a16802a17703a16301a56474797065a27538a3656e"
    "63a3726177a464617461c406020100050403a563616c696283a166cb4000000000000000a8626173656c696e65cb3fe000"
    "0000000000a5646f666673cb0000000000000000a5646570746884a46b696e64a6706f696e7473a16e01a27576c4080000"
    "803f00000000a17ac40400008040"
)


def test_documented_example_bytes():
    """The 2x3 example in docs/wire-format.md: exact bytes both ways."""
    left = np.arange(6, dtype=np.uint8).reshape(2, 3)
    z = np.full((2, 3), np.nan, np.float32)
    z[0, 1] = 4.0
    fr = StereoFrame(
        left=left,
        right=left[:, ::-1].copy(),
        calib=Calibration(f=2.0, baseline=0.5),
        sensor_depth=z,
        rig="r",
        seq=1,
        stamp_ns=2,
    )
    assert wire.encode_frame(fr).hex() == DOC_EXAMPLE_HEX
    out = wire.decode_frame(bytes.fromhex(DOC_EXAMPLE_HEX))
    np.testing.assert_array_equal(out.left, left)
    np.testing.assert_array_equal(out.right, [[2, 1, 0], [5, 4, 3]])
    assert out.sensor_depth[0, 1] == 4.0 and np.isfinite(out.sensor_depth).sum() == 1
    assert (out.rig, out.seq, out.stamp_ns, out.calib.f, out.calib.baseline) == ("r", 1, 2, 2.0, 0.5)


def test_output_roundtrip():
    fr = make_frame()
    disp = np.full(fr.shape, 3.5, np.float32)
    disp[0, 0] = np.nan
    res = FusionResult(
        frame=fr,
        disparity=disp,
        depth=disp * 2,
        left_vpp=fr.left,
        right_vpp=fr.right,
        timing_ms={"match": 1.5},
        metrics={"bad2": 4.0},
        vpp_stats={"projected": 2},
    )
    out = wire.decode_output(wire.encode_output(res, "disparity"))
    np.testing.assert_array_equal(out.data, disp)
    assert out.seq == 7 and out.timing_ms == {"match": 1.5} and out.metrics == {"bad2": 4.0}
    assert out.calib == fr.calib and out.extra["vpp"] == {"projected": 2}
    np.testing.assert_array_equal(wire.decode_output(wire.encode_output(res, "depth")).data, disp * 2)
    assert wire.encode_output(res, "confidence") is None  # not computed
    res.confidence = np.linspace(0, 1, disp.size, dtype=np.float32).reshape(disp.shape)
    conf = wire.decode_output(wire.encode_output(res, "confidence"))
    np.testing.assert_array_equal(conf.data, res.confidence)
    assert conf.seq == 7 and conf.calib == fr.calib and conf.data.dtype == np.float32
    seq, img = wire.decode_output_image(wire.encode_output(res, "left_vpp", "png"))
    assert seq == 7
    np.testing.assert_array_equal(img, fr.left)
    assert wire.encode_output(FusionResult(frame=fr, disparity=disp), "right_vpp") is None
    with pytest.raises(ValueError, match="name"):
        wire.encode_output(res, "bogus")


@pytest.mark.parametrize("shape", [(1, 1), (100, 100), (200, 200)])  # bin8, bin16, bin32 data
def test_output_parts_are_the_packb_message(shape):
    """The parts joined are byte for byte what msgpack.packb writes for the same map."""
    fr = make_frame()
    disp = np.random.default_rng(0).random(shape, dtype=np.float32)
    res = FusionResult(
        frame=fr,
        disparity=disp,
        depth=disp * 2,
        timing_ms={"match": 1.5, "vpp": 0.25},
        metrics={"bad2": 4.0},
        vpp_stats={"projected": 2, "occluded": 1},
    )
    for name, arr in (("disparity", disp), ("depth", disp * 2)):
        parts = wire.encode_output_parts(res, name)
        assert len(parts) == 2 and parts[1] == arr.astype("<f4").tobytes()
        fields = {
            "v": 1,
            "rig": fr.rig,
            "seq": fr.seq,
            "stamp_ns": fr.stamp_ns,
            "h": shape[0],
            "w": shape[1],
            "dtype": "f32",
            "calib": fr.calib.to_dict(),
            "timing_ms": {"match": 1.5, "vpp": 0.25},
        }
        if name == "disparity":
            fields.update(metrics={"bad2": 4.0}, vpp={"projected": 2, "occluded": 1})
        want = msgpack.packb({**fields, "data": arr.astype("<f4").tobytes()}, use_bin_type=True)
        assert b"".join(parts) == wire.encode_output(res, name) == want


@pytest.mark.parametrize(("nfields", "nblob"), [(0, 0), (14, 255), (15, 256), (20, 65535), (70000, 65536)])
def test_map_parts_headers(nfields, nblob):
    """Fixmap / map16 / map32 and bin8 / bin16 / bin32 headers, as packb writes them."""
    fields = {f"k{i}": i for i in range(nfields)}
    blob = bytes(range(256)) * (nblob // 256) + bytes(nblob % 256)
    assert b"".join(wire._map_parts(fields, "data", blob)) == msgpack.packb({**fields, "data": blob}, use_bin_type=True)


@pytest.mark.parametrize("part", ["left", "right", "depth"])
def test_parts_roundtrip(part):
    fr = make_frame()
    p = wire.decode_part(wire.encode_part(fr, part), part)
    assert p.seq == 7 and p.stamp_ns == 123456789
    if part == "depth":
        np.testing.assert_array_equal(p.sensor_depth, fr.sensor_depth)
    else:
        np.testing.assert_array_equal(p.image, getattr(fr, part))


def test_assemble_parts():
    fr = make_frame()
    parts = {k: wire.decode_part(wire.encode_part(fr, k), k) for k in ("left", "right", "depth")}
    out = wire.assemble(parts["left"], parts["right"], parts["depth"])
    np.testing.assert_array_equal(out.right, fr.right)
    assert out.calib == fr.calib and out.gt_disparity is not None


BIG = 1 << 40


@pytest.mark.parametrize(
    ("payload", "field"),
    [
        (b"", "message"),
        (raw_msg()[:-10], "message"),  # truncated
        (msgpack.packb([1, 2, 3]), "message"),  # not a map
        (b"\xc1\x00", "message"),  # invalid msgpack byte
        (raw_msg(v=2), "v"),
        (raw_msg(v="1"), "v"),
        (raw_msg(seq=-1), "seq"),
        (raw_msg(seq="7"), "seq"),
        (raw_msg(rig=5), "rig"),
        (raw_msg(left=KeyError), "left"),
        (raw_msg(calib={"f": math.nan, "baseline": 0.1}), "calib.f"),
        (raw_msg(calib={"f": 100.0, "baseline": math.inf}), "calib.baseline"),
        (raw_msg(calib={"f": -1.0, "baseline": 0.1}), "calib.f"),
        (raw_msg(calib={"f": 100.0}), "calib.baseline"),
        (raw_msg(calib=[1, 2]), "calib"),
        (raw_msg(rectified=1), "rectified"),
        (raw_msg(left={"h": BIG, "w": BIG, "c": 3, "dtype": "u8", "enc": "raw", "data": b""}), "left.h"),
        (raw_msg(left={"h": 16000, "w": 16000, "c": 3, "dtype": "u8", "enc": "raw", "data": b"x"}), "left.h"),
        (raw_msg(left={"h": 6, "w": 8, "c": 3, "dtype": "u8", "enc": "raw", "data": b"x" * 10}), "left.data"),
        (raw_msg(left={"h": 6, "w": 8, "c": 2, "dtype": "u8", "enc": "raw", "data": b"x" * 96}), "left.c"),
        (raw_msg(left={"h": 6, "w": 8, "c": 3, "dtype": "f32", "enc": "raw", "data": b"x" * 144}), "left.dtype"),
        (raw_msg(left={"h": 6, "w": 8, "c": 3, "dtype": "u8", "enc": "bmp", "data": b"x" * 144}), "left.enc"),
        (raw_msg(left={"h": 6, "w": 8, "c": 3, "dtype": "u8", "enc": "raw", "data": "text"}), "left.data"),
        (raw_msg(left={"h": 6, "w": 8, "c": 3, "dtype": "u8", "enc": "png", "data": b"notpng" * 10}), "left."),
        (raw_msg(left=wire.encode_image(np.zeros((4, 8, 3), np.uint8))), "right"),
        (raw_msg(depth={"kind": "points", "n": BIG, "uv": b"", "z": b""}), "depth.n"),
        (raw_msg(depth={"kind": "points", "n": 2, "uv": b"\0" * 8, "z": b"\0" * 8}), "depth.uv"),
        (
            raw_msg(
                depth={
                    "kind": "points",
                    "n": 1,
                    "uv": np.array([8.0, 1.0], "<f4").tobytes(),
                    "z": np.array([1.0], "<f4").tobytes(),
                }
            ),
            "depth.uv",
        ),
        (
            raw_msg(
                depth={
                    "kind": "points",
                    "n": 1,
                    "uv": np.array([1.0, -3.0], "<f4").tobytes(),
                    "z": np.array([1.0], "<f4").tobytes(),
                }
            ),
            "depth.uv",
        ),
        (
            raw_msg(
                depth={
                    "kind": "points",
                    "n": 1,
                    "uv": np.array([1.0, 1.0], "<f4").tobytes(),
                    "z": np.array([np.nan], "<f4").tobytes(),
                }
            ),
            "depth.z",
        ),
        *[
            (
                raw_msg(
                    depth={
                        "kind": "points",
                        "n": 3,
                        "uv": np.array(uv, "<f4").tobytes(),
                        "z": np.array([1.0, 2.0, 3.0], "<f4").tobytes(),
                    }
                ),
                "depth.uv",
            )
            for uv in (
                [1, 1, 2, np.nan, 3, 3],
                [1, 1, np.inf, 2, 3, 3],
                [1, 1, 2, 2, -0.6, 3],
                [1, 1, 2, 5.5, 3, 3],
                [7.5, 1, 2, 2, 3, 3],
                [1, -np.inf, 2, 2, 3, 3],
            )
        ],
        *[
            (
                raw_msg(
                    depth={
                        "kind": "disparity_points",
                        "n": 3,
                        "uv": np.array([1, 1, 2, 2, 3, 3], "<f4").tobytes(),
                        "d": np.array(d, "<f4").tobytes(),
                    }
                ),
                "depth.d",
            )
            for d in ([1.0, np.inf, 2.0], [1.0, 0.0, 2.0], [1.0, 2.0, -1.0], [np.nan, 1.0, 1.0])
        ],
        (raw_msg(depth={"kind": "map", "h": 6, "w": 8, "unit": "m", "data": b"\0" * 4}), "depth.data"),
        (raw_msg(depth={"kind": "map", "h": 5, "w": 8, "unit": "m", "data": b"\0" * 160}), "depth.h"),
        (raw_msg(depth={"kind": "map", "h": 6, "w": 8, "unit": "ft", "data": b"\0" * 192}), "depth.unit"),
        (raw_msg(depth={"kind": "mesh"}), "depth.kind"),
        (raw_msg(gt={"h": 6, "w": 8, "data": b"\0" * 3}), "gt.data"),
    ],
)
def test_malformed_frames_are_rejected(payload, field):
    with pytest.raises(WireError) as exc:
        wire.decode_frame(payload)
    assert str(exc.value).startswith(field), str(exc.value)


def test_points_on_the_rounding_border_are_accepted():
    uv = np.array([[-0.5, -0.5], [7.49, 5.49]], "<f4")
    m = {"kind": "disparity_points", "n": 2, "uv": uv.tobytes(), "d": np.array([2.0, 3.0], "<f4").tobytes()}
    _, disp = wire.decode_depth(m, 6, 8)
    assert disp[0, 0] == 2.0 and disp[5, 7] == 3.0 and np.isnan(disp).sum() == 46


def test_png_header_size_mismatch_is_rejected_before_decoding():
    big = wire.encode_image(np.zeros((64, 64), np.uint8), "png")
    with pytest.raises(WireError, match="declared 2x2"):
        wire.decode_image({**big, "h": 2, "w": 2}, "left")
    jpg = wire.encode_image(np.zeros((16, 24, 3), np.uint8), "jpeg")
    with pytest.raises(WireError, match="declared"):
        wire.decode_image({**jpg, "h": 24, "w": 16}, "left")


def test_message_size_limit():
    with pytest.raises(WireError, match="exceeds"):
        wire.decode_frame(raw_msg(), wire.WireLimits(max_message_bytes=100))


def test_unknown_keys_are_ignored():
    out = wire.decode_frame(raw_msg(future_field={"x": 1}))
    assert out.seq == 7


@pytest.mark.parametrize(
    ("bad", "exc"),
    [
        (np.zeros((2, 2), np.float32), TypeError),
        ([1, 2], TypeError),
        (np.zeros((2, 2, 4), np.uint8), ValueError),
        (np.zeros((0, 3), np.uint8), ValueError),
    ],
)
def test_encode_image_bad_input(bad, exc):
    with pytest.raises(exc, match="img"):
        wire.encode_image(bad)


def test_encode_frame_bad_input():
    with pytest.raises(TypeError, match="frame"):
        wire.encode_frame("nope")
    with pytest.raises(ValueError, match="enc"):
        wire.encode_frame(make_frame(), enc="gif")


@pytest.mark.parametrize(
    ("prefix", "rig", "message"),
    [
        ("", "r", "prefix must be a non-empty string"),
        ("vpp", "", "rig must be a non-empty string"),
        ("vpp/*", "r", "prefix must be a plain key expression"),
        ("vpp", "a/b", "rig must not contain '/'"),
        ("vpp", "r$", "rig must be a plain key expression"),
    ],
)
def test_topic_validation(prefix, rig, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        wire.topic(prefix, rig, "in/frame")


def test_topic():
    assert wire.topic("vpp", "rig0", "out/disparity") == "vpp/rig0/out/disparity"


def test_sparse_output_round_trip_and_errors():
    fr = make_frame()
    sparse = np.full(fr.shape, np.nan, np.float32)
    sparse[1, 2], sparse[4, 0] = 3.0, 9.5
    res = FusionResult(frame=fr.with_(sparse_disparity=sparse), disparity=np.ones(fr.shape, np.float32))
    out = wire.decode_output_points(wire.encode_output(res, "sparse"))
    assert (out.rig, out.seq, out.h, out.w) == (fr.rig, fr.seq, *fr.shape)
    assert out.points.tolist() == [[2.0, 1.0, 3.0], [0.0, 4.0, 9.5]]
    assert wire.encode_output(FusionResult(frame=fr.with_(sparse_disparity=None), disparity=sparse), "sparse") is None
    msg = msgpack.unpackb(wire.encode_output(res, "sparse"))
    for key, value, field in [
        ("data", np.float32([[99.0, 1.0, 3.0]] * 2).tobytes(), "inside"),
        ("data", np.float32([[1.0, 1.0, -3.0]] * 2).tobytes(), "> 0"),
        ("data", np.float32([[1.0, 1.0, np.nan]] * 2).tobytes(), "finite"),
        ("n", 3, "data"),
    ]:
        with pytest.raises(wire.WireError, match=field):
            wire.decode_output_points(msgpack.packb({**msg, key: value}, use_bin_type=True))


# ------------------------------------------------ hostile messages: caps before work
@pytest.mark.parametrize("kind", [k for k in hostile.KINDS if hostile.stage(k) in ("wire", "size")])
def test_every_hostile_kind_is_rejected_by_the_decoder(kind):
    cap = 4 << 20
    with pytest.raises(wire.WireError):
        wire.decode_frame(hostile.hostile_message(kind, 3, cap), wire.WireLimits(max_message_bytes=cap))


@pytest.mark.parametrize("kind", [k for k in hostile.KINDS if hostile.stage(k) == "rig"])
def test_hostile_rig_kinds_decode_with_the_forged_rig(kind):
    # well-formed frames: the pipeline rejects them by their rig (test_service_pipeline)
    assert wire.decode_frame(hostile.hostile_message(kind, 3)).rig != "rig0"


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("nested_empty_maps", "element limit"),
        ("unknown_key_nested", "element limit"),
        ("many_small_containers", "element limit|more than 4096 objects"),
        ("png_bomb", r"h\*w = 67108864 exceeds the limit of 8388608"),
        ("raw_declared_huge", "exceeds the limit of 8388608"),
        ("jpeg_marker_flood", "no JPEG frame header within 1024 markers"),
        ("png_bad_crc", "bad CRC"),
        ("png_corrupt_data", "truncated PNG stream"),
    ],
)
def test_caps_stop_hostile_messages_before_the_work(kind, match):
    cap = 16 << 20
    with pytest.raises(wire.WireError, match=match):
        wire.decode_frame(hostile.hostile_message(kind, 0, cap), wire.WireLimits(max_message_bytes=cap))


def test_default_pixel_cap_admits_full_resolution_middlebury():
    h, w = 1988, 2964
    img = wire.decode_image({"h": h, "w": w, "c": 3, "dtype": "u8", "enc": "raw", "data": bytes(h * w * 3)})
    assert img.shape == (h, w, 3)
    assert wire.DEFAULT_LIMITS.max_pixels >= h * w and wire.DEFAULT_LIMITS.max_message_bytes > 2 * h * w * 3


def test_depth_part_size_is_capped_before_allocating():
    msg = {"v": 1, "rig": "rig0", "seq": 0, "stamp_ns": 0, "h": 16384, "w": 16384}
    msg["depth"] = {"kind": "points", "n": 0, "uv": b"", "z": b""}
    with pytest.raises(wire.WireError, match="exceeds the limit of 8388608"):
        wire.decode_part(msgpack.packb(msg, use_bin_type=True), "depth")


def test_unknown_top_level_keys_are_skipped_not_built():
    good = msgpack.unpackb(wire.encode_frame(make_frame()), raw=False)
    msg = {**good, "x-future": {"a": list(range(100))}}
    frame = wire.decode_frame(msgpack.packb(msg, use_bin_type=True))
    assert frame.seq == 7
    too_many = {**good, "x-future": [[0] * 15] * 300}  # 4800 objects: over the element cap even unbuilt
    with pytest.raises(wire.WireError, match=r"element limit|more than 4096 objects"):
        wire.decode_frame(msgpack.packb(too_many, use_bin_type=True))


_QUIET_PROBE = r"""
import sys
sys.path.insert(0, "tests")
from helpers import hostile
from vpp_service.transport import wire
for kind in ("png_corrupt_data", "png_bad_crc", "jpeg_corrupt", "png_header_lies", "jpeg_marker_flood"):
    try:
        wire.decode_frame(hostile.hostile_message(kind, 1, 4 << 20), wire.WireLimits(max_message_bytes=4 << 20))
    except wire.WireError:
        pass
"""


def test_corrupt_images_are_rejected_without_decoder_noise_on_stderr():
    # libpng reports a corrupt stream on stderr itself, past any log rate limit: it must never see one
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run(
        [sys.executable, "-c", _QUIET_PROBE], capture_output=True, text=True, timeout=60, check=True, cwd=root
    )
    assert out.stderr == ""


# -- out/points ------------------------------------------------------------------------


@pytest.mark.parametrize("stride", [1, 4])
def test_points_output_round_trips(stride):
    """``out/points``: a msgpack header and the xyz / rgb blobs; decoded, it is the depth map's cloud."""
    from helpers.points import CALIB, assert_cloud_is_depth, clipped_result

    res = clipped_result(seq=5, rig="cam")
    payload = wire.encode_output(res, "points", points_stride=stride)
    assert payload is not None
    assert payload == b"".join(wire.encode_output_parts(res, "points", points_stride=stride) or [])
    raw = msgpack.unpackb(payload, raw=False)  # any msgpack library reads it: the documented layout
    assert sorted(raw) == sorted(["v", "rig", "seq", "stamp_ns", "h", "w", "stride", "calib", "n", "xyz", "rgb"])
    assert (raw["h"], raw["w"], raw["stride"]) == (64, 128, stride)
    xyz = np.frombuffer(raw["xyz"], "<f4").reshape(raw["n"], 3)
    rgb = np.frombuffer(raw["rgb"], np.uint8).reshape(raw["n"], 3)
    assert_cloud_is_depth(xyz, rgb, res, stride)
    cloud = wire.decode_output_cloud(payload)
    assert (cloud.rig, cloud.seq, cloud.stamp_ns, cloud.stride) == ("cam", 5, 1_000_005, stride)
    assert cloud.calib == CALIB
    np.testing.assert_array_equal(cloud.xyz, xyz)
    np.testing.assert_array_equal(cloud.rgb, rgb)


def test_points_output_needs_metric_depth():
    res = FusionResult(frame=make_frame(), disparity=np.ones((6, 8), np.float32), depth=None)
    assert wire.encode_output(res, "points") is None


def _points_message(**changes) -> bytes:
    n = 2
    msg = {
        "v": 1,
        "rig": "r",
        "seq": 0,
        "stamp_ns": 0,
        "h": 4,
        "w": 4,
        "stride": 2,
        "calib": {"f": 10.0, "baseline": 0.1},
        "n": n,
        "xyz": np.array([[0, 0, 1], [0.1, 0.2, 2]], "<f4").tobytes(),
        "rgb": bytes(3 * n),
    }
    msg.update(changes)
    return msgpack.packb(msg, use_bin_type=True)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"rgb": bytes(5)}, r"rgb: 5 bytes, need 6"),
        ({"xyz": bytes(20)}, r"xyz: expected 24 bytes"),
        ({"n": 5}, r"\bn\b"),  # more points than the 2 x 2 grid holds
        ({"stride": 0}, "stride"),
        ({"xyz": np.array([[0, 0, 1], [0, 0, 0]], "<f4").tobytes()}, "z must be > 0"),
        ({"xyz": np.array([[0, 0, 1], [np.nan, 0, 1]], "<f4").tobytes()}, "finite"),
        ({"calib": None}, "calib"),
    ],
)
def test_bad_points_messages_are_rejected(changes, match):
    assert wire.decode_output_cloud(_points_message()).xyz.shape == (2, 3)
    with pytest.raises(WireError, match=match):
        wire.decode_output_cloud(_points_message(**changes))
