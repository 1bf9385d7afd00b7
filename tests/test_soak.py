"""The fast part of ``benchmarks/soak.py``: every hostile kind against the running service, on loopback."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from helpers import hostile


def _soak() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "soak.py"
    spec = importlib.util.spec_from_file_location("soak", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["soak"] = module
    spec.loader.exec_module(module)
    return module


def test_generator_has_at_least_16_kinds_in_every_stage():
    assert len(hostile.KINDS) >= 16
    assert {hostile.stage(k) for k in hostile.KINDS} == {"size", "wire", "rig"}


def test_hostile_messages_interleaved_with_valid_frames():
    n_kinds = len(hostile.KINDS)
    figures = _soak().run(n_hostile=2 * n_kinds, n_valid=4, full_size=False, flood_mb=0.25)
    assert figures["crashes"] == 0 and figures["answering_at_end"]
    assert figures["processed"] == figures["sent_valid"] == 4 and figures["stalls"] == 0
    assert figures["sent_hostile"] == 2 * n_kinds
    # every hostile message is counted as rejected (none lost in a ring, none mistaken for a frame)
    assert figures["rejected"] == 2 * n_kinds and figures["ring_dropped"] == 0
    assert figures["received"] == 2 * n_kinds + 4
    assert figures["files_outside_sinks"] == [] and figures["files_written"] == figures["recorded"] == 4
    # valid frames carried stamps of 1970, 0 and the far future: latency is from receipt
    assert 0 <= figures["latency_p99_ms"] < 60_000


def test_ros2_mode_delivers_every_genuine_set_and_counts_every_sample():
    """Hostile parts with each set's stamp and a junk burst before it: every set delivered, every sample counted."""
    figures = _soak().run_ros2(n_sets=6, junk=24)
    assert figures["delivered"] == figures["processed"] == 6 and figures["stalls"] == 0
    by = figures["rejected_by"]
    assert by == {"encoding": 6, "layout": 6, "calibration": 6, "fields": 6, "attachment": 72, "too_large": 72}, by
    ledger = figures["messages"]
    assert figures["messages_accounted"] and ledger["received"] == 6 * (4 + 24 + 5), ledger
    assert ledger["used"] == 30 and ledger["ring_dropped"] == 0 and sum(figures["dropped"].values()) == 0
