"""Benchmark of vpp_service.vpp.project against the cost of copying the two images.

Prints a table (median and minimum milliseconds) and writes JSON.  "x copy"
is the median time over the median copy time, "x (min)" the fastest run over
the fastest copy (the cost with the least interference from the rest of a
shared machine, whose second core is sometimes busy for a whole block of
runs); "paired" is the median of per-run ratios with a copy right before each
run (robust to slow drift).  Sizes: KITTI 1242x375,
Middlebury half 1482x994 and full 2964x1988 (RGB); densities 1 % and 5 %;
patterns random (vi) and histogram (vii), default 3x3 / alpha 0.4 / FGD;
threads 1 and all (:func:`vpp_service.threads.resolve_threads`).  ``--quick``
runs a smaller subset.

Output: the JSON goes to ``--out`` (default ``out/benchmarks/``, not
committed), so a run never overwrites the committed results.
``--update-docs`` also writes the committed ``benchmarks/results/bench_vpp.json``
and regenerates the performance table of ``docs/algorithm.md`` (between the
``<!-- bench_vpp:begin -->`` and ``<!-- bench_vpp:end -->`` markers); it needs
the full run at the default repetitions, which the page describes.

Memory: by default freed memory is kept for reuse
(:func:`vpp_service.service.allocator.reuse_freed_memory`, as the service
does), so neither the copy nor VPP pays first-touch page faults for its
outputs.  Without it glibc sometimes maps a copy's 2 x 17.7 MB afresh and
sometimes not, so the copy reference would depend on the process; with it the
copy is at its fastest, the strictest reference.  ``--fresh-memory`` measures
without it.

OpenMP: :func:`vpp_service.threads.configure_openmp` sets the service's wait
policy before the kernels are imported (they are imported inside
:func:`main`, never at module level).
"""

from __future__ import annotations

import argparse
import json
import os
import re
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np
import numpy.typing as npt
from _harness import paired_ratio, times_ms

from vpp_service.service.allocator import reuse_freed_memory
from vpp_service.threads import configure_openmp, resolve_threads

ROOT = Path(__file__).resolve().parent.parent
#: Where a run writes its JSON unless told otherwise (git-ignored).
LOCAL_JSON = ROOT / "out" / "benchmarks" / "bench_vpp.json"
#: The committed results, written only with ``--update-docs``.
COMMITTED_JSON = ROOT / "benchmarks" / "results" / "bench_vpp.json"
#: The page whose performance table ``--update-docs`` regenerates.
DOC = ROOT / "docs" / "algorithm.md"
BEGIN, END = "<!-- bench_vpp:begin -->", "<!-- bench_vpp:end -->"

SIZES = {"kitti": (375, 1242), "midd_half": (994, 1482), "midd_full": (1988, 2964)}
DENSITIES = (0.01, 0.05)
PATTERNS = ("random", "histogram")
DEFAULT_REPS = 15

Image = npt.NDArray[np.uint8]
Disparity = npt.NDArray[np.float32]


class Row(TypedDict):
    """One result: the copy reference (``pattern == "copy"``) or one VPP call."""

    size: str
    H: int
    W: int
    density: float
    pattern: str
    threads: int
    ms: float
    min_ms: float
    ratio: float
    min_ratio: float
    paired_ratio: NotRequired[float]
    points: NotRequired[int]


class Report(TypedDict):
    """The JSON document: the machine, the build and the rows."""

    cpu_count: int
    cpu: NotRequired[str | None]
    avx2: NotRequired[bool]
    memory: str
    reps: NotRequired[int]
    results: list[Row]


def scene(H: int, W: int, density: float, seed: int = 0) -> tuple[Image, Image, Disparity]:
    """A textured RGB pair (8 x 8 blocks plus noise) and a sparse smooth disparity map.

    Parameters
    ----------
    H, W : int
        Image size.
    density : float
        Fraction of the pixels that carry a point.
    seed : int
        Seed of the random generator.

    Returns
    -------
    tuple of numpy.ndarray
        ``(left, right, disparity)``: H x W x 3 uint8, H x W x 3 uint8 (left
        shifted by 20 columns) and H x W float32 (0 = no point).
    """
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (H // 8 + 1, W // 8 + 1, 3), dtype=np.uint8)
    left = np.ascontiguousarray(np.repeat(np.repeat(small, 8, 0), 8, 1)[:H, :W])
    left = np.clip(left.astype(np.int16) + rng.integers(-8, 9, left.shape), 0, 255).astype(np.uint8)
    right = np.ascontiguousarray(np.roll(left, -20, axis=1))
    gt = 20 + 60 * np.sin(np.arange(W) / 150.0)[None, :] + np.arange(H)[:, None] / 20.0
    disp = np.where(rng.random((H, W)) < density, gt, 0).astype(np.float32)
    return left, right, disp


def cpu_model(cpuinfo: Path = Path("/proc/cpuinfo")) -> str | None:
    """The CPU's model name from ``cpuinfo`` (Linux), or None when it cannot be read."""
    try:
        text = cpuinfo.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() == "model name":
            return value.strip() or None
    return None


def _copy_pair(left: Image, right: Image) -> tuple[Image, Image]:
    return left.copy(), right.copy()


def _print_row(row: Row) -> None:
    paired = f"{row['paired_ratio']:7.2f}" if "paired_ratio" in row else ""
    points = f"{row['points']:8d}" if "points" in row else ""
    print(
        f"{row['size']:10s} {row['density']:5.2f} {row['pattern']:10s} {row['threads']:3d} {row['ms']:8.2f} "
        f"{row['min_ms']:8.2f} {row['ratio']:7.2f} {row['min_ratio']:7.2f} {paired} {points}".rstrip()
    )


def measure_scene(size: str, density: float, threads: Sequence[int], reps: int) -> list[Row]:
    """Time the copy and every pattern x thread count on one scene; print each row as it is measured.

    Parameters
    ----------
    size : str
        A key of :data:`SIZES`.
    density : float
        Fraction of the pixels that carry a point.
    threads : sequence of int
        Thread counts to run VPP with.
    reps : int
        Timed runs per entry (after one warm-up run).

    Returns
    -------
    list of Row
        The copy row, then one row per pattern and thread count.
    """
    from vpp_service.vpp import VPPConfig, project

    H, W = SIZES[size]
    left, right, disp = scene(H, W, density)
    copy = partial(_copy_pair, left, right)
    ct = times_ms(copy, reps)
    copy_ms, copy_min = float(np.median(ct)), float(ct.min())
    rows = [
        Row(
            size=size,
            H=H,
            W=W,
            density=density,
            pattern="copy",
            threads=1,
            ms=copy_ms,
            min_ms=copy_min,
            ratio=1.0,
            min_ratio=1.0,
        )
    ]
    _print_row(rows[-1])
    for pattern in PATTERNS:
        cfg = VPPConfig(pattern=pattern)
        for nt in threads:
            run = partial(project, left, right, disp, cfg, threads=nt)
            t = times_ms(run, reps)
            ms, mn = float(np.median(t)), float(t.min())
            rows.append(
                Row(
                    size=size,
                    H=H,
                    W=W,
                    density=density,
                    pattern=pattern,
                    threads=nt,
                    ms=ms,
                    min_ms=mn,
                    ratio=ms / copy_ms,
                    min_ratio=mn / copy_min,
                    paired_ratio=paired_ratio(run, copy, reps),
                    points=project(left, right, disp, cfg).stats.given,
                )
            )
            _print_row(rows[-1])
    return rows


def _ms(v: float) -> str:
    """Milliseconds with three significant digits (at least two decimals below 10)."""
    return f"{v:.0f}" if v >= 100 else f"{v:.1f}" if v >= 10 else f"{v:.2f}"


def _threads_label(n: int) -> str:
    return f"{n} thread" + ("s" if n > 1 else "")


def markdown_table(doc: Report) -> str:
    """The performance table of ``docs/algorithm.md``, with its caption line.

    One line per (image, density): the copy, the default pattern (vi) at each
    thread count, its ratio to the copy at the most threads, and the histogram
    pattern (vii) at each thread count (median milliseconds).

    Parameters
    ----------
    doc : Report
        A document as written by :func:`main` (``cpu`` and ``avx2`` are
        optional: without them the caption gives the CPU count and no build).

    Returns
    -------
    str
        The caption, a blank line and the Markdown table (no trailing newline).
    """
    rows = doc["results"]
    threads = sorted({r["threads"] for r in rows if r["pattern"] != "copy"})
    top = threads[-1]
    cell = {(r["size"], r["density"], r["pattern"], r["threads"]): r for r in rows}
    keys = list(dict.fromkeys((r["size"], r["density"]) for r in rows))
    head = ["image", "points", "copy"]
    head += [f"default (vi), {_threads_label(n)}" for n in threads] + [f"default (vi) / copy, {_threads_label(top)}"]
    head += [f"histogram (vii), {_threads_label(n)}" for n in threads]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 2 + "---:|" * (len(head) - 2)]
    for size, dens in keys:
        copy = cell[(size, dens, "copy", 1)]
        rnd = {n: cell[(size, dens, "random", n)] for n in threads}
        hist = {n: cell[(size, dens, "histogram", n)] for n in threads}
        out = [f"{copy['W']} x {copy['H']}", f"{dens * 100:g} % ({rnd[top]['points']:,})", _ms(copy["ms"])]
        out += [_ms(rnd[n]["ms"]) for n in threads] + [f"{rnd[top]['ratio']:.1f}"]
        out += [_ms(hist[n]["ms"]) for n in threads]
        lines.append("| " + " | ".join(out) + " |")
    cpu = doc.get("cpu") or f"{doc['cpu_count']} CPUs"
    avx2 = doc.get("avx2")
    build = "" if avx2 is None else ", AVX2 build" if avx2 else ", portable build"
    caption = f"Median ms of each call, including the output allocation; {cpu}{build}; freed memory {doc['memory']}."
    return caption + "\n\n" + "\n".join(lines)


def replace_block(text: str, block: str, *, source: str = "text") -> str:
    """``text`` with the one ``BEGIN ... END`` block's content replaced by ``block``.

    Parameters
    ----------
    text : str
        The page.
    block : str
        The new content between the markers (without them).
    source : str
        Name of the page in the error message.

    Returns
    -------
    str
        The new page; the markers stay, everything outside them is unchanged.

    Raises
    ------
    ValueError
        ``text`` does not hold exactly one marked block.
    """
    new = f"{BEGIN}\n{block}\n{END}"
    result, n = re.subn(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: new, text, flags=re.DOTALL)
    if n != 1:
        raise ValueError(f"{source}: expected one {BEGIN} ... {END} block, found {n}")
    return result


def update_doc(md_path: Path, doc: Report) -> None:
    """Regenerate the table of ``md_path`` from ``doc`` (see :func:`markdown_table`, :func:`replace_block`)."""
    md_path.write_text(replace_block(md_path.read_text(), markdown_table(doc), source=str(md_path)))


def write_json(path: Path, doc: Report) -> None:
    """Write ``doc`` as indented JSON to ``path``, creating its folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark (``--help`` for the options); write the JSON and, if asked, the docs."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=LOCAL_JSON, help="JSON output (default: out/benchmarks/bench_vpp.json)")
    ap.add_argument(
        "--update-docs",
        action="store_true",
        help="also write benchmarks/results/bench_vpp.json and the table in docs/algorithm.md",
    )
    ap.add_argument("--quick", action="store_true", help="a smaller subset (not with --update-docs)")
    ap.add_argument("--reps", type=int, default=DEFAULT_REPS, help="timed runs per entry (default: %(default)s)")
    ap.add_argument(
        "--fresh-memory", action="store_true", help="do not keep freed memory for reuse (outputs may be mapped afresh)"
    )
    a = ap.parse_args(argv)
    if a.update_docs and (a.quick or a.reps != DEFAULT_REPS):
        ap.error(f"--update-docs needs the full run with --reps {DEFAULT_REPS} (the page describes it)")
    configure_openmp()  # the service's OpenMP wait policy; before the kernels load
    from vpp_service.vpp import backend

    memory = "fresh"
    if not a.fresh_memory and reuse_freed_memory():
        memory = "reused"
    print(f"memory: {memory}, build: {'AVX2' if backend.AVX2 else 'portable'}")
    threads = sorted({1, resolve_threads(None)})
    print(
        f"{'size':10s} {'dens':>5s} {'pattern':10s} {'thr':>3s} {'ms':>8s} {'min ms':>8s} {'x copy':>7s} "
        f"{'x (min)':>7s} {'paired':>7s} {'points':>8s}"
    )
    rows: list[Row] = []
    for size in ["kitti", "midd_half"] if a.quick else list(SIZES):
        for density in [0.05] if a.quick else DENSITIES:
            rows += measure_scene(size, density, threads, a.reps)
    doc = Report(
        cpu_count=os.cpu_count() or 1,
        cpu=cpu_model(),
        avx2=backend.AVX2,
        memory=memory,
        reps=a.reps,
        results=rows,
    )
    write_json(a.out, doc)
    print(f"wrote {a.out}")
    if a.update_docs:
        update_doc(DOC, doc)  # first: a page without its markers stops the update before any file changes
        write_json(COMMITTED_JSON, doc)
        print(f"wrote {COMMITTED_JSON} and the table in {DOC}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
