"""Evaluation: metrics, the runner comparing matcher / guided / VPP, and reports.

>>> from vpp_service.evaluation import compute_metrics, run_evaluation, summarize
"""

from vpp_service.evaluation.metrics import compute_metrics, metric_key
from vpp_service.evaluation.progress import ProgressBar
from vpp_service.evaluation.report import markdown_report, plot_sweep, summarize, write_json, write_markdown
from vpp_service.evaluation.runner import METHODS, default_max_disparity, run_evaluation

__all__ = [
    "METHODS",
    "ProgressBar",
    "compute_metrics",
    "default_max_disparity",
    "markdown_report",
    "metric_key",
    "plot_sweep",
    "run_evaluation",
    "summarize",
    "write_json",
    "write_markdown",
]
