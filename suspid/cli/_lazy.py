"""Names a subcommand module uses only when its command runs, imported at that moment.

``suspid X --help`` builds the parser of ``X`` alone, and its module must not load numpy's
heavier neighbours, scipy, matplotlib, python-can, asammdf or Dask to print it. A
subcommand module therefore imports the library functions its ``run`` calls through
:func:`lazy_names`, with the real import under ``TYPE_CHECKING`` for the type checker and
the import linter::

    if TYPE_CHECKING:
        from estimator.stream.compare import compare, plot
    else:
        compare, plot = lazy_names("estimator.stream.compare", "compare", "plot")

Each name is a stand-in that imports its module on first use (a call, an attribute) and
then forwards to the real object; the call sites stay as they are.
"""
from __future__ import annotations

import importlib
from typing import Any

__all__ = ["LazyName", "lazy_names"]


class LazyName:
    """Stand-in for ``module.name``, imported on first use.

    Parameters
    ----------
    module : str
        Dotted module path.
    name : str
        Attribute of that module (a function, class or constant).
    """

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

    def __repr__(self) -> str:
        return f"<lazy {self._module}.{self._name}>"


def lazy_names(module: str, *names: str) -> tuple[LazyName, ...]:
    """One :class:`LazyName` per name of ``module``, in the order given.

    Parameters
    ----------
    module : str
        Dotted module path, imported when one of the names is first used.
    *names : str
        Attributes of that module.

    Returns
    -------
    tuple of LazyName
    """
    return tuple(LazyName(module, n) for n in names)
