"""Suspension models (the physics). ``get_model(name)`` returns a fresh model instance.

Besides the built-ins, installed packages add models through the entry-point group
``suspid.models`` (a built-in name cannot be replaced); see ``docs/architecture.md``.
"""
from __future__ import annotations

from collections.abc import Mapping
from importlib.metadata import entry_points
from typing import Callable, Iterable, Iterator

from suspid.errors import UsageError
from suspid.models.base import (GRAVITY, AffinePieces, DoeDesign, ParamSpec, Site, SuspensionModel,
                                Twin)
from suspid.models.full7 import Full7
from suspid.models.half4 import Half4
from suspid.models.quarter1 import Quarter1
from suspid.models.quarter2 import Quarter2

#: entry-point group other packages register models under
ENTRY_POINT_GROUP = "suspid.models"

ModelFactory = Callable[[], SuspensionModel]

#: the built-in models
BUILTIN: dict[str, ModelFactory] = {"quarter1": Quarter1, "quarter2": Quarter2, "half4": Half4,
                                    "full7": Full7}


class _Registry(Mapping[str, ModelFactory]):
    """``name -> factory`` of every model: the built-ins, then the entry points (loaded once)."""

    def __init__(self) -> None:
        self._items: dict[str, ModelFactory] = dict(BUILTIN)
        self._loaded = False

    def _load(self) -> dict[str, ModelFactory]:
        if not self._loaded:
            self._loaded = True
            for ep in entry_points(group=ENTRY_POINT_GROUP):
                if ep.name in BUILTIN:
                    continue
                try:
                    factory = ep.load()
                except Exception as exc:  # a broken plug-in is named, in one line
                    raise UsageError(f"model entry point {ep.name!r} ({ep.value}) cannot be "
                                     f"loaded: {type(exc).__name__}: {exc}") from None
                if not callable(factory):
                    raise UsageError(f"model entry point {ep.name!r} ({ep.value}) is not a class "
                                     f"or factory; expected a SuspensionModel subclass")
                self._items[ep.name] = factory
        return self._items

    def reload(self) -> None:
        """Forget the loaded entry points (after installing a package at run time)."""
        self._items = dict(BUILTIN)
        self._loaded = False

    def __getitem__(self, key: str) -> ModelFactory:
        return self._load()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._load())

    def __len__(self) -> int:
        return len(self._load())


#: every model by name (built-ins and entry points)
MODELS = _Registry()


def model_names() -> list[str]:
    """Names of every registered model (built-ins first)."""
    return list(MODELS)


def get_model(name: str) -> SuspensionModel:
    """Return a new instance of the model called ``name`` (UsageError naming the known ones)."""
    if name not in MODELS:
        raise UsageError(f"unknown model {name!r}; expected one of {', '.join(MODELS)}")
    model = MODELS[name]()
    if not isinstance(model, SuspensionModel):
        raise UsageError(f"model {name!r}: its factory returned {type(model).__name__}, "
                         f"expected a SuspensionModel")
    return model


def infer_model(columns: Iterable[str]) -> str:
    """The model whose CSV columns these are (UsageError if none owns any).

    Of the models owning every recognised column base the one with the fewest bases wins;
    without one, the model owning most of the columns.
    """
    cols = {c.strip() for c in columns}
    scored = []
    for order, name in enumerate(MODELS):
        try:
            bases = get_model(name).column_bases()
        except UsageError:  # a broken plug-in cannot be the CSV's model (get_model names it)
            continue
        mine = {b for b in bases if cols & {b, f"{b}_dot", f"{b}_ddot"}}
        scored.append((name, bases, mine, order))
    known = set().union(*(m for _, _, m, _ in scored))
    if not known:
        raise UsageError(f"cannot tell the model from the CSV columns "
                         f"({', '.join(sorted(cols)) or 'none'}); give --model ({', '.join(MODELS)})")
    best = min(scored, key=lambda s: (s[2] != known, -len(s[2]), len(s[1]), s[3]))
    return best[0]


__all__ = ["AffinePieces", "BUILTIN", "DoeDesign", "ENTRY_POINT_GROUP", "GRAVITY", "MODELS", "ParamSpec", "Site",
           "SuspensionModel", "Twin", "get_model", "infer_model", "model_names", "Quarter1", "Quarter2",
           "Half4", "Full7"]
