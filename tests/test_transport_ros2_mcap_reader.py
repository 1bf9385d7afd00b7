"""Damaged .mcap bags: every readable message is played, bit for bit; each damaged place is reported by cause.

The bags are written with rosbags (helpers/damaged_bags.write_test_bag: 20 stamps of the five stereo topics,
128 x 160 RGB images, about 2.5 MB in three chunks, rosbags closing a chunk past 1 MiB), uncompressed or
zstd, with the chunk CRCs filled in as ros2 bag record writes them (helpers/damaged_bags.seal_chunk_crcs).
What is expected is derived from the intact file, independently of the reader: a cut file keeps every
message whose bytes all lie before the cut (uncompressed chunks hold the CDR bytes verbatim, so
``bytes.find`` locates each), and at least every message of the chunks wholly before it (zstd); a
garbled chunk loses exactly its own messages (helpers/damaged_bags.mcap_chunks lists them).
"""

from __future__ import annotations

import struct
import tracemalloc
from pathlib import Path

import pytest

from helpers.damaged_bags import cut, garble, mcap_chunks, write_test_bag
from vpp_service.transport.ros2.bag import bag_topics, read_bag
from vpp_service.transport.ros2.mcap_reader import MAGIC, MAX_RECORD_BYTES

TOPICS = {
    "/stereo/left/image_rect": "sensor_msgs/msg/Image",
    "/stereo/right/image_rect": "sensor_msgs/msg/Image",
    "/stereo/left/camera_info": "sensor_msgs/msg/CameraInfo",
    "/stereo/right/camera_info": "sensor_msgs/msg/CameraInfo",
    "/stereo/points": "sensor_msgs/msg/PointCloud2",
}


@pytest.fixture(scope="module", params=["plain", "zstd", "no_crc"])
def intact(request, tmp_path_factory) -> tuple[str, Path]:
    """(kind, .mcap file): uncompressed or zstd chunks with CRCs (ros2 bag record), or rosbags' own (CRC 0)."""
    folder = tmp_path_factory.mktemp(request.param) / "bag"
    f = write_test_bag(folder, "mcap", zstd=request.param == "zstd", crc=request.param != "no_crc")
    assert len(mcap_chunks(f)) == 3
    return request.param, f


def read(path: Path) -> tuple[list, list]:
    damage: list = []
    return list(read_bag(path, on_damage=damage.append)), damage


@pytest.mark.parametrize("fraction", [0.5, 0.9, 0.99])
def test_a_cut_file_plays_every_message_before_the_cut(intact, tmp_path, fraction):
    kind, f = intact
    ref, none = read(f)
    assert len(ref) == 100 and not none
    data = f.read_bytes()
    damaged = cut(f, tmp_path / "cut.mcap", fraction)
    at = damaged.stat().st_size
    got, damage = read(damaged)
    assert got == ref[: len(got)]  # bit for bit, in order, up to the break
    if kind == "zstd":
        whole = sum(len(c.log_times) for c in mcap_chunks(f) if c.end <= at)
        assert whole <= len(got) <= 100
    else:
        assert len(got) == sum(1 for m in ref if data.find(m.data) + len(m.data) <= at)
    assert [d.cause for d in damage] == ["bag.truncated"]
    assert f"ends at byte {at}" in damage[0].where and str(damaged) in damage[0].where
    assert f"after {len(got)} messages" in damage[0].where
    assert bag_topics(damaged) == TOPICS  # from the records, the summary being gone


def test_garbage_in_a_chunk_skips_that_chunk_only(intact, tmp_path):
    kind, f = intact
    ref, _ = read(f)
    mid = f.stat().st_size // 2
    (hit,) = [i for i, c in enumerate(mcap_chunks(f)) if c.start < mid < c.end - 4096]
    got, damage = read(garble(f, tmp_path / "garbled.mcap", at=mid))
    if kind == "no_crc":  # nothing to check the bytes against: the garbage goes unseen (documented)
        assert not damage and len(got) == 100 and sum(a != b for a, b in zip(got, ref, strict=True)) == 1
        return
    lost = set(mcap_chunks(f)[hit].log_times)
    assert got == [m for m in ref if m.log_time_ns not in lost]
    # random pixels do not compress: zstd keeps them in raw blocks, which decode garbage and all; the CRC sees it
    assert [d.cause for d in damage] == ["bag.crc"]
    assert f"chunk {hit + 1} at byte {mcap_chunks(f)[hit].start} skipped" in damage[0].where


@pytest.mark.parametrize("head", ["random", "data end"])
def test_broken_framing_skips_to_the_next_indexed_chunk(intact, tmp_path, head):
    """Chunk 2's opcode and length overwritten with random bytes, or with a Data End record's.

    A Data End ends the data section only where the summary starts; anywhere else it is broken framing.
    """
    _, f = intact
    ref, _ = read(f)
    chunks = mcap_chunks(f)
    damaged = garble(f, tmp_path / "framing.mcap", at=chunks[1].start, n=9)
    if head == "data end":
        data = bytearray(damaged.read_bytes())
        data[chunks[1].start : chunks[1].start + 9] = b"\x0f" + struct.pack("<Q", 4)
        damaged.write_bytes(bytes(data))
    got, damage = read(damaged)
    assert got == [m for m in ref if m.log_time_ns not in set(chunks[1].log_times)]
    assert [d.cause for d in damage] == ["bag.corrupt_record"]
    assert f"at byte {chunks[1].start}" in damage[0].where and f"chunk at byte {chunks[2].start}" in damage[0].where


def test_a_footer_pointing_into_the_data_is_not_believed(intact, tmp_path):
    """The footer's summary offset (8 bytes at 37 - 9 from the end) moved onto chunk 2: every message is still read."""
    _, f = intact
    ref, _ = read(f)
    data = bytearray(f.read_bytes())
    data[-28:-20] = struct.pack("<Q", mcap_chunks(f)[1].start)
    (tmp_path / "footer.mcap").write_bytes(bytes(data))
    got, damage = read(tmp_path / "footer.mcap")
    assert got == ref
    assert [d.cause for d in damage] == ["bag.corrupt_record"] and "follows no Data End" in damage[0].where


def test_nothing_readable_is_an_error_naming_the_file_and_the_cause(intact, tmp_path):
    _, f = intact
    with pytest.raises(ValueError, match=r"nothing readable.*bag\.truncated.*ends at byte 100") as err:
        list(read_bag(cut(f, tmp_path / "stub.mcap", 100 / f.stat().st_size + 1e-9)))
    assert str(tmp_path / "stub.mcap") in str(err.value)
    (tmp_path / "junk.mcap").write_bytes(b"\0" * 4096)
    with pytest.raises(ValueError, match="not an MCAP file"):
        list(read_bag(tmp_path / "junk.mcap"))


def record(op: int, content: bytes, length: int | None = None) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(content) if length is None else length) + content


def test_hostile_lengths_allocate_nothing(tmp_path):
    header = record(0x01, struct.pack("<I", 4) + b"ros2" + struct.pack("<I", 0))
    # a chunk claiming 2^63 - 1 bytes in a file of a few: the file was cut (no footer)
    huge = tmp_path / "huge.mcap"
    huge.write_bytes(MAGIC + header + record(0x06, b"\0" * 64, length=2**63 - 1))
    # a chunk of valid framing whose uncompressed size is 1 TiB: refused before decompressing
    body = struct.pack("<QQQI", 0, 0, 2**40, 0) + struct.pack("<I", 4) + b"zstd" + struct.pack("<Q", 16) + b"\0" * 16
    bomb = tmp_path / "bomb.mcap"
    footer = record(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    bomb.write_bytes(MAGIC + header + record(0x06, body) + record(0x0F, b"\0" * 4) + footer)
    tracemalloc.start()
    try:
        for path, cause in ((huge, "bag.truncated"), (bomb, "bag.corrupt_chunk")):
            damage: list = []
            with pytest.raises(ValueError, match="nothing readable"):
                list(read_bag(path, on_damage=damage.append))
            assert [d.cause for d in damage] == [cause]
        assert tracemalloc.get_traced_memory()[1] < 4 * 2**20
    finally:
        tracemalloc.stop()
    assert MAX_RECORD_BYTES < 2**40


def test_an_intact_bag_reads_as_rosbags_reads_it(intact):
    _, f = intact
    from rosbags.rosbag2 import Reader

    with Reader(f) as reader:
        want = [(c.topic, c.msgtype, ts, bytes(raw)) for c, ts, raw in reader.messages()]
    got, damage = read(f)
    assert [(m.topic, m.ros_type, m.log_time_ns, m.data) for m in got] == want and not damage


def string(s: str) -> bytes:
    return struct.pack("<I", len(s)) + s.encode()


def one_chunk_mcap(compression: str, payload: bytes) -> tuple[bytes, int]:
    """A minimal MCAP built from the specification, and the byte offset of its one chunk.

    Magic, header, one chunk (schema, channel, two messages; its CRC the CRC-32 of the uncompressed
    records), data end, footer without a summary.
    """
    from binascii import crc32

    import lz4.frame

    from helpers.damaged_bags import zstd

    records = (
        record(0x03, struct.pack("<H", 1) + string("std_msgs/msg/String") + string("ros2msg") + string("string data"))
        + record(0x04, struct.pack("<HH", 7, 1) + string("/chatter") + string("cdr") + struct.pack("<I", 0))
        + record(0x05, struct.pack("<HIQQ", 7, 0, 10, 10) + payload)
        + record(0x05, struct.pack("<HIQQ", 7, 1, 20, 20) + payload[::-1])
    )
    packed = {"": records, "zstd": zstd.compress(records), "lz4": lz4.frame.compress(records)}[compression]
    chunk = struct.pack("<QQQI", 10, 20, len(records), crc32(records)) + string(compression)
    chunk += struct.pack("<Q", len(packed)) + packed
    head = MAGIC + record(0x01, string("ros2") + string("test"))
    footer = record(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    return head + record(0x06, chunk) + record(0x0F, struct.pack("<I", 0)) + footer, len(head)


@pytest.mark.parametrize("compression", ["", "zstd", "lz4"])
def test_each_chunk_compression_reads_and_damage_to_it_is_seen(tmp_path, compression):
    payload = bytes(4096) + b"\1" * 4096  # compressible: garbage in the compressed stream breaks it
    data, at = one_chunk_mcap(compression, payload)
    (tmp_path / "ok.mcap").write_bytes(data)
    got, damage = read(tmp_path / "ok.mcap")
    assert [(m.topic, m.ros_type, m.log_time_ns, m.data) for m in got] == [
        ("/chatter", "std_msgs/msg/String", 10, payload),
        ("/chatter", "std_msgs/msg/String", 20, payload[::-1]),
    ]
    assert not damage
    bad = bytearray(data)
    body = at + 9 + 28 + 4 + len(compression) + 8  # the chunk's (compressed) records
    bad[body + 40 : body + 48] = b"\xa5" * 8
    (tmp_path / "bad.mcap").write_bytes(bytes(bad))
    damage = []
    with pytest.raises(ValueError, match="nothing readable"):
        list(read_bag(tmp_path / "bad.mcap", on_damage=damage.append))
    # zstd's sequences break; lz4 (no content checksum in lz4.frame's default) decodes the garbage: the CRC sees it
    assert [d.cause for d in damage] == ["bag.corrupt_chunk" if compression == "zstd" else "bag.crc"]
    assert f"chunk 1 at byte {at}" in damage[0].where
