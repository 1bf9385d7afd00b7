"""Summaries and reports of evaluation results: JSON, Markdown tables, density plots.

``summarize`` averages every numeric metric over scenes, per method. With one
density the summary is ``{method: {metric: mean}}``; with a density sweep
(several densities in the results) it is ``{method: {density: {metric: mean}}}``,
the density written as a string key (``"0.05"``, JSON keys are strings).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from vpp_service.evaluation.runner import METHODS, ResultRow, RowValue

#: A JSON value (what :func:`write_json` writes).
JSON = dict[str, "JSON"] | list["JSON"] | str | int | float | bool | None
#: Means of a group of rows: metric -> mean over scenes, plus ``scenes`` (their number).
Means = dict[str, float]
#: :func:`summarize`'s result: ``{method: Means}``, or ``{method: {density key: Means}}`` for a sweep.
Summary = dict[str, Means] | dict[str, dict[str, Means]]

#: Row fields that are not averaged into a summary.
_NOT_AVERAGED = {"density", "max_disparity", "n", "n_nocc"}
#: Columns of the Markdown tables (when present).
TABLE_METRICS = ("bad1", "bad2", "bad3", "bad4", "avg", "rms", "bad2_nocc", "avg_nocc", "n_points", "ms")


def _method_order(rows: Iterable[ResultRow]) -> list[str]:
    seen = {str(r["method"]) for r in rows}
    return [m for m in METHODS if m in seen] + sorted(seen - set(METHODS))


def _mean(values: Iterable[RowValue]) -> float:
    vals = [v for v in values if isinstance(v, (int, float)) and not (isinstance(v, float) and math.isnan(v))]
    return float(sum(vals) / len(vals)) if vals else float("nan")


def _average(rows: list[ResultRow]) -> Means:
    keys: list[str] = []
    for r in rows:
        for k, v in r.items():
            if k not in keys and k not in _NOT_AVERAGED and isinstance(v, (int, float)) and not isinstance(v, bool):
                keys.append(k)
    out = {k: _mean([r.get(k) for r in rows]) for k in keys}
    out["scenes"] = len({r["scene"] for r in rows})
    return out


def density_key(d: float | None) -> str:
    """String key of a density in summaries (``"0.05"``)."""
    return "measured" if d is None else f"{d:g}"


def _density(row: ResultRow) -> float | None:
    """The row's density (None for a sensor reported without one)."""
    d = row["density"]
    if d is not None and not isinstance(d, (int, float)):
        raise TypeError(f"rows: density must be a number or None, got {d!r}")
    return d


def _none_last(d: float | None) -> tuple[bool, float]:
    """Sort key of densities: ascending, None (measured) last."""
    return d is None, d or 0.0


def is_sweep(rows: list[ResultRow]) -> bool:
    """True when the results hold more than one (uniform) density."""
    return len({r.get("density") for r in rows if r.get("sensor") == "uniform"}) > 1


def summarize(rows: list[ResultRow]) -> Summary:
    """Mean of each metric per method (and per density in a sweep); see module docs."""
    if not isinstance(rows, list):
        raise TypeError(f"rows: must be a list of result dicts, got {type(rows).__name__}")
    by_method = {method: [r for r in rows if r["method"] == method] for method in _method_order(rows)}
    if not is_sweep(rows):
        return {method: _average(mrows) for method, mrows in by_method.items()}
    out: dict[str, dict[str, Means]] = {}
    for method, mrows in by_method.items():
        groups: dict[float | None, list[ResultRow]] = defaultdict(list)
        for r in mrows:
            groups[_density(r)].append(r)
        out[method] = {density_key(d): _average(groups[d]) for d in sorted(groups, key=_none_last)}
    return out


def json_safe(obj: object) -> JSON:
    """``obj`` as JSON values: non-finite floats -> None, numpy scalars -> Python, tuples -> lists, keys -> str.

    Raises
    ------
    TypeError
        A value JSON cannot hold (e.g. an arbitrary object).
    """
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, (str, int, float)):  # bool is an int
        return obj
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (np.generic, np.ndarray)):  # numpy scalars (and 1-element arrays)
        return json_safe(obj.item())
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")


def write_json(path: str | Path, rows: list[ResultRow], config: Mapping[str, object] | None = None) -> dict[str, JSON]:
    """Write ``{"config", "results", "summary"}`` to ``path`` (NaN -> null); return the document."""
    doc: dict[str, JSON] = {
        "config": json_safe(dict(config or {})),
        "results": json_safe(rows),
        "summary": json_safe(summarize(rows)),
    }
    Path(path).write_text(json.dumps(doc, indent=2) + "\n")
    return doc


def _fmt(v: RowValue) -> str:
    if isinstance(v, bool) or v is None:
        return "-"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        return f"{v:.2f}"
    return str(v)


def _table(header: list[str], lines: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(line) + " |" for line in lines]
    return "\n".join(out)


def markdown_report(rows: list[ResultRow], per_scene: bool = False, title: str = "VPP evaluation") -> str:
    """Markdown text: one table of means per (dataset, matcher), optionally per-scene tables.

    Columns: bad-1..4 (%), avg and rms error (px), non-occluded bad-2 / avg when
    a mask exists, points and run time (ms); rows: method (x density in a sweep).
    """
    parts = [f"# {title}", ""]
    groups: dict[tuple[str, str], list[ResultRow]] = defaultdict(list)
    for r in rows:
        groups[(str(r.get("dataset", "")), str(r.get("matcher", "")))].append(r)
    for (dataset, matcher), grows in groups.items():
        cols = [c for c in TABLE_METRICS if any(c in r for r in grows)]
        sweep = is_sweep(grows)
        n_scenes = len({r["scene"] for r in grows})
        sensor = ", ".join(sorted({str(r.get("sensor", "")) for r in grows}))
        parts += [f"## {dataset or 'frames'} - {matcher} ({n_scenes} scenes, sensor {sensor})", ""]
        header = ["method", "density", *cols]
        lines = []
        for method in _method_order(grows):
            mrows = [r for r in grows if r["method"] == method]
            densities = sorted({_density(r) for r in mrows}, key=_none_last)
            for d in densities:
                avg = _average([r for r in mrows if r["density"] == d])
                dtxt = f"{d:.3g}" if isinstance(d, float) else _fmt(d)
                lines.append([method, dtxt] + [_fmt(avg.get(c)) for c in cols])
        parts += [_table(header, lines), ""]
        if per_scene:
            parts += ["### Per scene", ""]
            header = ["scene", "method", "density", *cols]
            lines = [
                [str(r["scene"]), str(r["method"]), f"{r['density']:.3g}"] + [_fmt(r.get(c)) for c in cols]
                for r in grows
            ]
            parts += [_table(header, lines), ""]
        if sweep:
            parts += ["(bad-τ in %, errors in px; means over scenes.)", ""]
    if len(parts) == 2:
        parts.append("No results.")
    return "\n".join(parts).rstrip() + "\n"


def write_markdown(
    path: str | Path, rows: list[ResultRow], per_scene: bool = False, title: str = "VPP evaluation"
) -> str:
    """Write :func:`markdown_report` to ``path``; return the text."""
    text = markdown_report(rows, per_scene=per_scene, title=title)
    Path(path).write_text(text)
    return text


def plot_sweep(path: str | Path, rows: list[ResultRow], metric: str = "bad2", title: str | None = None) -> None:
    """Plot ``metric`` (mean over scenes) against density, one line per method; save to ``path`` (PNG).

    Uses matplotlib's Agg backend (no display needed).
    """
    import matplotlib as mpl

    mpl.use("Agg", force=True)
    import matplotlib.pyplot as plt

    uniform = [r for r in rows if r.get("density") is not None]
    if not uniform:
        raise ValueError("rows: no results with a density to plot")
    if not any(metric in r for r in uniform):
        raise ValueError(f"metric: {metric!r} is not in the results")
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    for method in _method_order(uniform):
        groups: dict[float, list[ResultRow]] = defaultdict(list)
        for r in uniform:
            d = _density(r)
            if r["method"] == method and d is not None:
                groups[d].append(r)
        xs = sorted(groups)
        ys = [_mean([r.get(metric) for r in groups[x]]) for x in xs]
        ax.plot([100 * x for x in xs], ys, marker="o", label=method)
    ax.set_xlabel("sparse points (% of valid GT pixels)")
    ax.set_ylabel(f"{metric} (%)" if metric.startswith("bad") else f"{metric} (px)")
    matchers = sorted({str(r.get("matcher", "")) for r in uniform})
    ax.set_title(title or f"{metric} vs density ({', '.join(matchers)})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(str(path), format="png")
    plt.close(fig)


def error_map(disparity: np.ndarray, gt: np.ndarray, tau: float = 2.0) -> np.ndarray:
    """RGB uint8 map of ``disparity``'s errors: green within ``tau`` px, red beyond, grey no value, black no GT.

    Raises
    ------
    ValueError
        ``disparity`` and ``gt`` differ in shape.
    """
    if disparity.shape != gt.shape:
        raise ValueError(f"disparity {disparity.shape} and gt {gt.shape} differ in shape")
    has_gt = np.isfinite(gt) & (gt > 0)
    has_value = np.isfinite(disparity)
    out = np.zeros((*gt.shape, 3), np.uint8)
    bad = np.zeros(gt.shape, bool)
    bad[has_gt & has_value] = np.abs(disparity[has_gt & has_value] - gt[has_gt & has_value]) > tau
    out[has_gt & has_value & ~bad] = (60, 170, 60)
    out[bad] = (220, 40, 40)
    out[has_gt & ~has_value] = (128, 128, 128)
    return out


def plot_comparison(
    path: str | Path,
    image: np.ndarray,
    gt: np.ndarray,
    maps: Mapping[str, tuple[np.ndarray, str]],
    title: str,
) -> None:
    """Save a PNG comparing disparity maps with ground truth: the maps, their bad-2 error maps, one colour bar.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    image : ndarray
        The (painted) left image shown beside the ground truth, H x W x 3 RGB or H x W uint8.
    gt : ndarray
        Ground-truth disparity (NaN / <= 0 = none).
    maps : mapping
        ``{name: (disparity, caption)}``, e.g. baseline and VPP with their scores.
    title : str
        Figure title.
    """
    import matplotlib as mpl

    mpl.use("Agg", force=True)
    import matplotlib.pyplot as plt

    valid = np.isfinite(gt) & (gt > 0)
    vmax = float(np.max(gt[valid])) if valid.any() else 1.0
    cmap = mpl.colormaps["turbo"].with_extremes(bad="black")
    cols = max(len(maps), 2)
    fig, axes = plt.subplots(3, cols, figsize=(5.5 * cols, 12), dpi=90, squeeze=False, layout="constrained")
    axes[0][0].imshow(image, cmap="gray" if image.ndim == 2 else None)
    axes[0][0].set_title("left image, as the matcher saw it", fontsize=10)
    im = axes[0][1].imshow(np.where(valid, gt, np.nan), cmap=cmap, vmin=0, vmax=vmax)
    axes[0][1].set_title("ground truth (black: none)", fontsize=10)
    for ax in axes[0][2:]:
        ax.set_visible(False)
    for k, (name, (disp, caption)) in enumerate(maps.items()):
        axes[1][k].imshow(np.where(np.isfinite(disp), disp, np.nan), cmap=cmap, vmin=0, vmax=vmax)
        axes[1][k].set_title(f"{name} (black: no value)\n{caption}", fontsize=10)
        axes[2][k].imshow(error_map(disp, gt))
        axes[2][k].set_title(f"{name}: bad-2 pixels", fontsize=10)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[:2, :].ravel().tolist(), shrink=0.7, label="disparity [px]")
    fig.suptitle(f"{title}\nerror maps: red off by > 2 px, green within 2 px, grey no value, black no ground truth")
    fig.savefig(str(path), format="png")
    plt.close(fig)


__all__ = [
    "JSON",
    "Means",
    "Summary",
    "density_key",
    "error_map",
    "is_sweep",
    "json_safe",
    "markdown_report",
    "plot_comparison",
    "plot_sweep",
    "summarize",
    "write_json",
    "write_markdown",
]
