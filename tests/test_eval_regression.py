"""Accuracy regression guard on real data: the issue's acceptance criterion.

On all Middlebury 2005/2006 third-size scenes with ``census-sgm`` at 5 % uniform
points (seed 0, default VPP config), VPP's mean bad-2 must be at most 0.6x the
matcher alone and below guided stereo, the matcher alone at most 10.6 % (the
paper's rSGM pipeline on these scenes) and VPP at most 5.0 %. Compared against the benchmark's ground
truth; if a change to VPP, the matcher or the harness makes VPP quietly worse,
this fails. Takes ~30-60 s on 2 cores.
"""

import pytest

from helpers.shared_data import need_shared
from vpp_service.datasets import open_dataset
from vpp_service.evaluation.report import summarize
from vpp_service.evaluation.runner import run_evaluation


@pytest.mark.slow
def test_vpp_beats_baseline_and_guided_on_middlebury2006():
    dataset = open_dataset("auto", need_shared("middlebury2005_2006_thirdsize"))
    assert len(dataset) == 26
    rows = run_evaluation(dataset, "census-sgm", ("baseline", "guided", "vpp"), 0.05, seed=0)
    assert len(rows) == 3 * 26
    summary = summarize(rows)
    base, guided, vpp = (summary[m]["bad2"] for m in ("baseline", "guided", "vpp"))
    assert vpp <= 0.6 * base, (base, guided, vpp)
    assert vpp < guided < base, (base, guided, vpp)
    assert base <= 10.6, (base, guided, vpp)
    assert vpp <= 5.0, (base, guided, vpp)
