"""Zero-copy msgpack decoding (vpp_service.transport.msgview) against msgpack itself."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from vpp_service.transport.msgview import Limits, MsgViewError, loads

BIG = Limits(max_bin_len=1 << 30, max_str_len=1 << 30, max_array_len=1 << 30, max_map_len=1 << 30)


def _plain(v):
    """Memoryview -> bytes, recursively (what msgpack.unpackb returns)."""
    if isinstance(v, memoryview):
        return v.tobytes()
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats(allow_nan=False)
    | st.text(max_size=300)
    | st.binary(max_size=300)
)
objects = st.recursive(
    scalars,
    lambda c: st.lists(c, max_size=20) | st.dictionaries(st.text(max_size=20) | st.binary(max_size=8), c, max_size=20),
    max_leaves=60,
)


@settings(max_examples=300, deadline=None)
@given(obj=objects, single_float=st.booleans())
def test_reference_equality_with_msgpack(obj, single_float):
    try:
        payload = msgpack.packb(obj, use_bin_type=True, use_single_float=single_float)
    except OverflowError:  # a float64 beyond float32's range, with single floats
        assume(False)
    ref = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    assert _plain(loads(payload, BIG)) == ref


@pytest.mark.parametrize(
    "obj",
    [
        0,
        127,
        128,
        255,
        256,
        65535,
        65536,
        2**32 - 1,
        2**32,
        2**64 - 1,
        -1,
        -32,
        -33,
        -128,
        -129,
        -32768,
        -32769,
        -(2**31),
        -(2**31) - 1,
        -(2**63),
        "",
        "a" * 31,
        "a" * 32,
        "é" * 200,
        "x" * 70000,
        b"",
        b"\0" * 255,
        b"\0" * 256,
        b"\1" * 70000,
        [],
        [1] * 15,
        [1] * 16,
        [1] * 70000,
        {},
        {str(i): i for i in range(15)},
        {str(i): i for i in range(16)},
        1.5,
        -0.0,
        float("inf"),
    ],
)
def test_every_length_and_width_class(obj):
    payload = msgpack.packb(obj, use_bin_type=True)
    assert _plain(loads(payload, BIG)) == msgpack.unpackb(payload, raw=False)


def test_bin_is_a_readonly_view_of_the_payload():
    data = np.arange(1000, dtype=np.float32)
    payload = msgpack.packb({"a": {"data": data.tobytes()}}, use_bin_type=True)
    v = loads(payload, BIG)["a"]["data"]
    assert isinstance(v, memoryview) and v.readonly
    arr = np.frombuffer(v, dtype=np.float32)
    np.testing.assert_array_equal(arr, data)
    assert np.shares_memory(arr, np.frombuffer(payload, np.uint8))  # no copy


@pytest.mark.parametrize("buf_type", [bytes, bytearray, memoryview])
def test_payload_types(buf_type):
    payload = msgpack.packb({"k": [1, b"xy"]}, use_bin_type=True)
    assert _plain(loads(buf_type(payload), BIG)) == {"k": [1, b"xy"]}


def test_every_truncation_is_an_error():
    payload = msgpack.packb(
        {"v": 1, "s": "abc", "b": b"\1" * 300, "l": [1.5, -7, None, True], "m": {"x": 2**40}}, use_bin_type=True
    )
    for n in range(len(payload)):
        with pytest.raises(MsgViewError, match="truncated"):
            loads(payload[:n], BIG)


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (msgpack.packb(1) + b"\x00", "trailing"),
        (b"\xc1", "never used"),
        (b"\xd4\x01\x00", "extension"),
        (b"\xc7\x01\x05\x00", "extension"),
        (msgpack.packb({1: 2}), "map key"),
        (b"\x81\x91\x01\x02", "map key"),  # {[1]: 2}
        (b"\xa2\xff\xfe", "not UTF-8"),
        (b"\x91" * 40 + b"\x00", "nesting"),
    ],
)
def test_malformed(payload, match):
    with pytest.raises(MsgViewError, match=match):
        loads(payload, BIG)


@pytest.mark.parametrize(
    ("obj", "field"),
    [
        (b"x" * 11, "bin length"),
        ("x" * 11, "string length"),
        ([0] * 11, "array length"),
        ({str(i): 0 for i in range(11)}, "map length"),
    ],
)
def test_limits(obj, field):
    lim = Limits(max_bin_len=10, max_str_len=10, max_array_len=10, max_map_len=10)
    payload = msgpack.packb(obj, use_bin_type=True)
    with pytest.raises(MsgViewError, match=field):
        loads(payload, lim)
    small = msgpack.packb(obj[:10] if not isinstance(obj, dict) else dict(list(obj.items())[:10]), use_bin_type=True)
    loads(small, lim)  # at the limit: accepted


def test_huge_declared_length_fails_fast():
    # a bin32 claiming 4 GiB in a 10-byte message: limit error, nothing allocated
    with pytest.raises(MsgViewError, match="bin length"):
        loads(b"\xc6\xff\xff\xff\xff" + b"\0" * 5, Limits(10, 10, 10, 10))
    with pytest.raises(MsgViewError, match="truncated"):
        loads(b"\xdd\x00\x00\x00\x05\x01", BIG)  # array of 5 with 1 element


def test_non_contiguous_buffer_is_rejected():
    with pytest.raises(MsgViewError, match="contiguous"):
        loads(memoryview(bytes(range(20)))[::2], BIG)


# ------------------------------------------------ total element count, skipped keys
def _limits(max_elements: int) -> Limits:
    return Limits(1 << 20, 1 << 20, 1 << 16, 1 << 12, max_elements=max_elements)


def test_total_element_count_is_capped_across_nesting():
    # 100 small arrays of 15 empty maps: every container is short, the total (1 + 100 * 16) is not
    obj = [[{}] * 15] * 100
    payload = msgpack.packb(obj)
    assert loads(payload, _limits(1601)) == obj
    with pytest.raises(MsgViewError, match="exceeds the element limit"):
        loads(payload, _limits(1600))


def test_a_container_header_cannot_claim_more_than_the_budget():
    payload = b"\xdd\x00\x00\xea\x60" + b"\x80" * 60000  # an array of 60000 empty maps
    with pytest.raises(MsgViewError, match="exceeds the element limit"):
        loads(payload, _limits(4096))


def test_keep_skips_unknown_top_level_values_unbuilt():
    msg = {"v": 1, "x-ext": {"a": [1, 2.5, "s", b"b", None, True, {"n": -3}] * 3}, "rig": "r"}
    payload = msgpack.packb(msg, use_bin_type=True)
    assert loads(payload, _limits(100), keep=frozenset({"v", "rig"})) == {"v": 1, "rig": "r"}
    assert loads(payload, _limits(100)) == msg


@pytest.mark.parametrize(
    ("junk", "match"),
    [
        (b"\xdd\x00\x00\x00\x02\xc0", "truncated"),  # the skipped array is short of one element
        (b"\xc1", "0xc1"),
        (b"\xd4\x01\x00", "extension type"),
        (b"\x91" * 40 + b"\xc0", "nesting deeper"),
        (b"\xdc\x01\x00" + b"\x80" * 256, "exceeds the element limit"),
        (
            b"\x9f" + (b"\x9f" + b"\x80" * 15) * 15,
            "element limit|more than 100 objects",
        ),  # short containers, many objects
    ],
)
def test_skipped_values_are_still_checked(junk, match):
    payload = b"\x82\xa1v\x01\xa4junk" + junk
    with pytest.raises(MsgViewError, match=match):
        loads(payload, _limits(100), keep=frozenset({"v"}))
