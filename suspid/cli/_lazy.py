"""Names a subcommand module uses only when its command runs, imported at that moment, so
``suspid X --help`` loads no scipy, matplotlib, python-can or Dask::

    if TYPE_CHECKING:
        from estimator.stream.compare import compare, plot
    else:
        compare, plot = lazy_names("estimator.stream.compare", "compare", "plot")
"""
from __future__ import annotations

import importlib
from typing import Any

__all__ = ["LazyName", "lazy_names"]


class LazyName:
    """Stand-in for ``module.name`` (dotted module path, attribute), imported on first use."""

    __slots__ = ("_module", "_name", "_target")

    def __init__(self, module: str, name: str) -> None:
        self._module = module
        self._name = name
        self._target: Any = None

    def resolve(self) -> Any:
        """The real object (its module is imported on the first call)."""
        if self._target is None:
            self._target = getattr(importlib.import_module(self._module), self._name)
        return self._target

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.resolve()(*args, **kwargs)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.resolve(), attr)

    def __instancecheck__(self, obj: Any) -> bool:
        return isinstance(obj, self.resolve())


def lazy_names(module: str, *names: str) -> tuple[LazyName, ...]:
    """One :class:`LazyName` per attribute ``names`` of the dotted ``module``, in order."""
    return tuple(LazyName(module, n) for n in names)
