"""vpp-service models list: the stereo networks in the models folder and their cards.

The models folder is where the psmnet matcher looks when its config names no
model: $VPP_SERVICE_MODELS, else the user cache folder (~/.cache/vpp-service/models).
Each .onnx file is listed with its card (the .toml beside it, or the preset's
built-in card for a known file name): the network's disparity range, colour
order, padding and licence. The project never downloads nor bundles weights:
see docs/deep-matchers.md for how to get PSMNet's.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vpp_service.cli.help import HelpFormatter, plain


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``models`` sub-command."""
    p = subparsers.add_parser(
        "models",
        help="list the stereo networks in the models folder",
        description=plain(__doc__),
        formatter_class=HelpFormatter,
    )
    p.add_argument("action", choices=["list"], help="list: the .onnx files and their cards")
    p.add_argument("--dir", type=Path, help="models folder (default: $VPP_SERVICE_MODELS, else the user cache)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """Print one line per model: file, card name, range, colour, padding, licence."""
    from vpp_service.matchers.model_store import MODELS_ENV, list_models, models_dir
    from vpp_service.matchers.onnx import BUILTIN_CARDS

    folder = args.dir if args.dir is not None else models_dir()
    found = list_models(folder, BUILTIN_CARDS)
    if not found:
        print(
            f"vpp-service models: no .onnx in {folder} (set ${MODELS_ENV} or put models there; "
            "docs/deep-matchers.md says how to get PSMNet)",
            file=sys.stderr,
        )
        return 0
    print(f"models in {folder}:")
    for m in found:
        if m.card is None:
            why = m.error or f"no card: write {m.path.with_suffix('.toml').name} beside it"
            print(f"  {m.path.name}: {why}")
            continue
        c = m.card
        size = f"fixed {c.input_size[0]}x{c.input_size[1]}" if c.fixed else f"pad x{c.pad_multiple}"
        print(
            f"  {m.path.name}: {c.name or '-'} | range {c.max_disparity} | {c.colour} | {size} | "
            f"licence: {c.licence or 'not stated'}"
        )
    return 0
