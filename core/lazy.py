"""Public names of a package loaded on first use (PEP 562): a room's ``__init__`` says which
module each of its public names lives in, and reading a CSV does not load the whole room."""

from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any


def public_names(package: str, public: Mapping[str, str]) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package``: ``public`` maps each name to its module."""

    def getattr_(name: str) -> Any:
        if name in public:
            return getattr(import_module(f"{package}.{public[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return getattr_
