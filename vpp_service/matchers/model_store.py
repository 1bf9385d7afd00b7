"""The models folder: where network matchers look for a model the config does not name.

``$VPP_SERVICE_MODELS`` when set, else the user cache folder
(``$XDG_CACHE_HOME/vpp-service/models``, by default ``~/.cache/vpp-service/models``).
The project never downloads or bundles weights: the user puts (or converts) a
model there, with its card beside it (``name.onnx`` + ``name.toml``), and names
it by file name (:func:`find_model`: ``model=psmnet_kitti2015.onnx``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from vpp_service.matchers.model_card import ModelCard, find_card, read_card

#: Environment variable naming the models folder.
MODELS_ENV = "VPP_SERVICE_MODELS"


def models_dir() -> Path:
    """The models folder (it may not exist): ``$VPP_SERVICE_MODELS``, else ``<user cache>/vpp-service/models``."""
    env = os.environ.get(MODELS_ENV, "").strip()
    if env:
        return Path(env).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(cache).expanduser() if cache else Path.home() / ".cache") / "vpp-service" / "models"


def find_model(model: str, key: str = "model") -> Path:
    """The file ``model`` names: a path as given, or a relative one in the working directory, then the models folder.

    So ``model=psmnet_kitti2015.onnx`` finds the file :func:`models_dir`
    holds (``models export`` writes it there) unless the working directory has one of that name.

    Raises
    ------
    FileNotFoundError
        Nowhere; names ``key`` and every place looked in.
    """
    p = Path(model).expanduser()
    if p.is_file():
        return p
    if p.is_absolute():
        raise FileNotFoundError(f"{key}: no such file: {p}")
    stored = models_dir() / p
    if stored.is_file():
        return stored
    raise FileNotFoundError(
        f"{key}: no such file: {model} (looked in the working directory {Path.cwd()} and the models folder "
        f"{models_dir()}, ${MODELS_ENV} or the user cache)"
    )


@dataclass(frozen=True)
class StoredModel:
    """One ``.onnx`` file of the models folder and its card.

    Attributes
    ----------
    path : Path
        The model file.
    card : ModelCard or None
        Its card (the ``.toml`` beside it, else the shipped card whose
        ``model_file`` is that file name), None when it has none.
    error : str
        Why its card could not be read ("" when it could or there is none).
    """

    path: Path
    card: ModelCard | None
    error: str = ""


def list_models(folder: Path | None = None, builtin: dict[str, ModelCard] | None = None) -> list[StoredModel]:
    """The ``.onnx`` files of ``folder`` (default :func:`models_dir`) with their cards, sorted by name.

    Parameters
    ----------
    folder : Path or None
        Folder to list (missing: an empty list).
    builtin : dict or None
        Shipped cards by model file name (their ``model_file``, for a file without a card beside it).
    """
    folder = models_dir() if folder is None else folder
    if not folder.is_dir():
        return []
    out = []
    for p in sorted(folder.glob("*.onnx")):
        card_file = find_card(p)
        if card_file is None:
            out.append(StoredModel(p, (builtin or {}).get(p.name)))
            continue
        try:
            out.append(StoredModel(p, read_card(card_file)))
        except (OSError, ValueError) as exc:
            out.append(StoredModel(p, None, str(exc).splitlines()[0]))
    return out


__all__ = ["MODELS_ENV", "StoredModel", "find_model", "list_models", "models_dir"]
