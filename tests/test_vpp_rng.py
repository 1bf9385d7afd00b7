"""The seeded pattern table (vpp_service.vpp.rng) and its compiled builder."""

from __future__ import annotations

import numpy as np
import pytest

from vpp_service.vpp import backend, rng

BUILDS = [backend.portable] + ([backend.avx2_build()] if backend.AVX2 else [])


def _splitmix(seed: int, key: int) -> int:
    """Scalar, pure-Python splitmix64 finaliser (the documented formula)."""
    m = rng.MASK64
    z = (seed * rng.SEED_MUL + key * rng.KEY_MUL) & m
    z = ((z ^ (z >> 30)) * rng.M1) & m
    z = ((z ^ (z >> 27)) * rng.M2) & m
    return z ^ (z >> 31)


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**64 - 1])
def test_pattern_hash_matches_scalar_formula(seed):
    xs = np.array([0, 1, 7, 2**31, 2**32 - 1], np.uint64)
    for y in (0, 3):
        got = rng.pattern_hash(seed, xs, y)
        want = [_splitmix(seed, (y << 32) | int(x)) for x in xs]
        assert [int(v) for v in got] == want


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("seed", [0, 7, 2**63 + 5])
def test_table_is_the_documented_byte_stream(seed, channels):
    t = rng.pattern_table(seed, channels)
    assert t.dtype == np.uint8 and t.shape == (rng.TABLE_SIZE * channels,)
    for i in (0, 1, 7, 8, 9, 1000, t.size - 1):
        assert t[i] == (_splitmix(seed, i // 8 + 1) >> (8 * (i % 8))) & 255
    assert not t.flags.writeable


def test_pattern_bytes_reference_equality():
    seed, C = 11, 3
    t = rng.pattern_table(seed, C)
    xs = np.array([0, 5, 1241, 65535, 65536, 70000])
    ys = np.array([0, 3, 374, 1, 2, 1987])
    got = rng.pattern_bytes(seed, xs, ys, C)
    assert got.shape == (6, 3)
    for (x, y), v in zip(zip(xs, ys, strict=True), got, strict=True):
        i = (int(x) + int(y) * rng.ROW_STEP) % rng.TABLE_SIZE
        np.testing.assert_array_equal(v, t[3 * i : 3 * i + 3])


def test_values_are_uniform_bytes():
    t = rng.pattern_table(0, 3)
    counts = np.bincount(t, minlength=256)
    expected = t.size / 256
    chi2 = float(((counts - expected) ** 2 / expected).sum())
    assert chi2 < 400  # 255 degrees of freedom: p ~ 1e-8 at 400
    assert len(np.unique(rng.pattern_bytes(0, np.arange(2000), 0, 3), axis=0)) == 2000


def test_no_repeat_within_rows_and_near_rows():
    """Two pixels share a table entry only if dx + dy * ROW_STEP = 0 (mod 2**16).

    So never within a row, never for |dy| <= 16 and |dx| < 1000, nowhere within 274 px.
    """
    N, M = rng.TABLE_SIZE, rng.ROW_STEP
    assert M % 2 == 1
    for dy in range(1, 17):
        dx = (-dy * M) % N
        assert min(dx, N - dx) >= 1000, dy
    shortest = min(np.hypot(min((dy * M) % N, N - (dy * M) % N), dy) for dy in range(1, 2000))
    assert shortest >= 274
    # brute force on a patch of the image plane: all (x, y) in 300 x 17 are distinct entries
    x, y = np.meshgrid(np.arange(300), np.arange(17))
    assert len(np.unique(rng.pattern_index(x, y))) == x.size


@pytest.mark.parametrize("build", BUILDS, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize(("channels", "hmax"), [(1, 0), (3, 1), (3, 4), (1, 7)])
def test_compiled_table_equals_reference(build, channels, hmax):
    seed = 987654321
    pad = build.table_padding(channels, hmax)
    assert pad >= (2 * hmax + 1) * channels + 16
    out = np.full(rng.TABLE_SIZE * channels + pad, 77, np.uint8)
    build.fill_pattern_table(seed, out, channels)
    ref = rng.pattern_table(seed, channels)
    np.testing.assert_array_equal(out[: ref.size], ref)
    np.testing.assert_array_equal(out[ref.size :], ref[:pad])  # padding repeats the start


@pytest.mark.parametrize("build", BUILDS, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_compiled_index_constants_match_reference(build):
    assert (build.TABLE_SIZE, build.ROW_STEP) == (rng.TABLE_SIZE, rng.ROW_STEP)


def test_kernel_table_cached_and_padded():
    a = rng.kernel_table(3, 3, 1)
    assert a is rng.kernel_table(3, 3, 1)
    assert not a.flags.writeable
    assert a.size == rng.TABLE_SIZE * 3 + backend.sweep.table_padding(3, 1)
    np.testing.assert_array_equal(a[: rng.TABLE_SIZE * 3], rng.pattern_table(3, 3))


@pytest.mark.parametrize(
    ("args", "exc", "match"),
    [
        ((-1, 3, 1), ValueError, "seed"),
        ((2**64, 3, 1), ValueError, "seed"),
        ((1.5, 3, 1), TypeError, "seed"),
        ((0, 0, 1), ValueError, "channels"),
        ((0, True, 1), ValueError, "channels"),
        ((0, 3, -1), ValueError, "hmax"),
        ((0, 3, 1.0), ValueError, "hmax"),
    ],
)
def test_kernel_table_rejects_bad_arguments(args, exc, match):
    with pytest.raises(exc, match=match):
        rng.kernel_table(*args)


def test_fill_rejects_short_buffer():
    with pytest.raises(ValueError, match="need at least"):
        backend.sweep.fill_pattern_table(0, np.zeros(100, np.uint8), 3)


def test_sweep_rejects_short_table():
    from vpp_service.vpp import VPPConfig
    from vpp_service.vpp.params import kernel_params

    d = np.zeros((4, 8), np.float32)
    img = np.zeros((4, 8, 3), np.uint8)
    params = kernel_params(VPPConfig(occlusion="off"))
    for table in (np.zeros(rng.TABLE_SIZE * 3, np.uint8), None):
        with pytest.raises(ValueError, match="pattern table"):
            backend.sweep.paint(d, np.zeros((4, 8), np.uint8), img, img, img.copy(), img.copy(), params, table, 1)
