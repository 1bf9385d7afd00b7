"""Tests of vpp_service.vpp.VPPConfig validation and dict round trip."""

from __future__ import annotations

import dataclasses

import pytest

from vpp_service.settings import from_mapping
from vpp_service.vpp import VPPConfig


def test_defaults_are_the_paper_variant():
    c = VPPConfig()
    assert (c.pattern, c.patch, c.uniform_patch, c.alpha, c.splat, c.occlusion) == (
        "random",
        3,
        False,
        0.4,
        True,
        "fgd",
    )


def test_round_trip():
    c = VPPConfig(pattern="histogram", patch=5, adaptive_patch="bilateral", alpha=0.2, adaptive_max_disparity=12.5)
    assert from_mapping(VPPConfig, c.to_dict()) == c


def test_from_mapping_rejects_unknown_keys():
    with pytest.raises(ValueError, match="bogus"):
        from_mapping(VPPConfig, {"bogus": 1})


@pytest.mark.parametrize(
    ("field", "value", "exc"),
    [
        ("pattern", "stripes", ValueError),
        ("patch", 4, ValueError),
        ("patch", 0, ValueError),
        ("patch", 3.0, TypeError),
        ("alpha", 1.5, ValueError),
        ("alpha", float("nan"), ValueError),
        ("splat", 1, TypeError),
        ("occlusion", "yes", ValueError),
        ("search_width", 0, ValueError),
        ("search_height", 2, ValueError),
        ("occ_window_x", 8, ValueError),
        ("occ_gamma", 2.0, ValueError),
        ("occ_lambda", -1.0, ValueError),
        ("adaptive_patch", "x", ValueError),
        ("adaptive_gamma", 0.0, ValueError),
        ("adaptive_max_disparity", -3.0, ValueError),
        ("bilateral_threshold", 1.0, ValueError),
        ("bilateral_sigma_space", 0.0, ValueError),
        ("uniform_patch", "no", TypeError),
    ],
)
def test_invalid_field_named(field, value, exc):
    with pytest.raises(exc, match=field):
        VPPConfig(**{field: value})


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'alpha'"):
        VPPConfig().alpha = 0.3
