"""The rmw_zenoh attachment: golden vector of the contract, both layouts, malformed input."""

from __future__ import annotations

import pytest
import zenoh.ext

from vpp_service.transport.ros2 import attachment
from vpp_service.transport.ros2.errors import Ros2Error

GID = bytes(range(16))
GOLDEN = bytes.fromhex("070000000000000015cd853dfe9c971710000102030405060708090a0b0c0d0e0f")
TS = 1700000000123456789


def test_golden_vector():
    att = attachment.Attachment(7, TS, GID)
    assert attachment.encode(att) == GOLDEN
    assert len(GOLDEN) == attachment.CURRENT_SIZE == 33
    assert attachment.decode(GOLDEN) == (att, "current")


def test_current_layout_equals_zenoh_serialize():
    ser = zenoh.ext.z_serialize((zenoh.ext.Int64(7), zenoh.ext.Int64(TS), GID)).to_bytes()
    assert ser == GOLDEN


def test_legacy_layout():
    att = attachment.Attachment(7, TS, GID)
    b = attachment.encode(att, "legacy")
    assert len(b) == 77
    assert b[:16] == b"\x0fsequence_number" and b[24:41] == b"\x10source_timestamp"
    assert b[49:60] == b"\x0asource_gid" and b[60] == 16 and b[61:] == GID
    ser = zenoh.ext.z_serialize(
        ("sequence_number", zenoh.ext.Int64(7), "source_timestamp", zenoh.ext.Int64(TS), "source_gid", GID)
    ).to_bytes()
    assert b == ser
    assert attachment.decode(b) == (att, "legacy")


def test_negative_values_roundtrip():
    att = attachment.Attachment(-1, -(2**63), b"\xff" * 16)
    assert attachment.decode(attachment.encode(att))[0] == att


@pytest.mark.parametrize(
    "data",
    [
        None,
        b"",
        GOLDEN[:-1],
        GOLDEN + b"\0",
        GOLDEN[:16] + b"\x0f" + GOLDEN[17:],
        attachment.encode(attachment.Attachment(1, 2, GID), "legacy").replace(b"source_gid", b"source_gix"),
        attachment.encode(attachment.Attachment(1, 2, GID), "legacy")[:-1] + b"\0\0",
    ],
)
def test_malformed_rejected(data):
    with pytest.raises(Ros2Error) as err:
        attachment.decode(data)
    assert err.value.reason == "attachment"


@pytest.mark.parametrize(("seq", "gid"), [(2**63, GID), (1, GID[:15]), (True, GID)])
def test_bad_fields(seq, gid):
    with pytest.raises(ValueError, match="must be"):
        attachment.Attachment(seq, 0, gid)
