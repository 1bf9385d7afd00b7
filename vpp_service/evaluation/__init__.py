"""Evaluation: the runner comparing matcher / guided / VPP, and reports (the metrics: :mod:`vpp_service.metrics`).

>>> from vpp_service.evaluation import run_evaluation, summarize
"""

from vpp_service.evaluation.progress import ProgressBar
from vpp_service.evaluation.report import markdown_report, plot_sweep, summarize, write_json, write_markdown
from vpp_service.evaluation.runner import METHODS, default_max_disparity, run_evaluation

__all__ = [
    "METHODS",
    "ProgressBar",
    "default_max_disparity",
    "markdown_report",
    "plot_sweep",
    "run_evaluation",
    "summarize",
    "write_json",
    "write_markdown",
]
