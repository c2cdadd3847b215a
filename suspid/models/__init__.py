"""Suspension models (the physics). ``get_model(name)`` returns a fresh model instance."""
from __future__ import annotations

from suspid.errors import UsageError
from suspid.models.base import ParamSpec, SuspensionModel
from suspid.models.half4 import Half4
from suspid.models.quarter1 import Quarter1
from suspid.models.quarter2 import Quarter2

MODELS: dict[str, type[SuspensionModel]] = {"quarter1": Quarter1, "quarter2": Quarter2, "half4": Half4}


def get_model(name: str) -> SuspensionModel:
    """Return a new instance of the model called ``name``.

    Raises
    ------
    UsageError
        For an unknown name, listing the known ones.
    """
    try:
        return MODELS[name]()  # type: ignore[call-arg]
    except KeyError:
        raise UsageError(f"unknown model {name!r}; expected one of {', '.join(MODELS)}") from None


__all__ = ["MODELS", "ParamSpec", "SuspensionModel", "get_model", "Quarter1", "Quarter2", "Half4"]
