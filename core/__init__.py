"""baseparams: base inertial parameters of mechanisms.

The Python front door (docs/api.md)::

    import baseparams as bp
    solution = bp.solve("puma560")                  # a registered name, a TOML or URDF file
    fit = bp.identify("pendulum", "data.csv", effects=["viscous_friction:*"])
    report = bp.diagnose("pendulum", "data.csv")

``load``, ``solve``, ``validate``, ``simulate``, ``identify``, ``diagnose``, ``export``,
``convert`` and ``excite`` return the objects the command line prints (``to_json()``,
``to_text()``, ``to_frame()``). They are imported on first use, so ``import baseparams``
stays fast; the command line is ``baseparams`` or ``python -m baseparams``.
"""

import os
import types
from typing import TYPE_CHECKING, Any

# Our matrices are small (thousands of rows, tens of columns): BLAS threads only contend for
# the cores. With OpenBLAS's default threads diagnose on the TX40 spent 50 CPU s for 30 s of
# wall time in the CLI, dp 10-40 times its single-thread CPU time (docs/urdf.md); through the
# Python API on a loaded 2-core machine bp.diagnose took 438 s against 23 s (docs/api.md).
# Effective only when numpy is not imported yet; a user's own setting wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

__version__ = "0.1.0"

API = ("load", "solve", "validate", "simulate", "identify", "diagnose", "export", "convert", "excite")
__all__ = ["__version__", *API]

if TYPE_CHECKING:
    from baseparams.api import convert, diagnose, excite, export, identify, load, simulate, solve, validate


def __getattr__(name: str) -> Any:
    """The API functions, imported from :mod:`baseparams.api` on first use, and ``bp.api``
    itself (``bp.api.DEFAULT_SOLVER``)."""
    if name in API or name == "api":
        import importlib
        api = importlib.import_module(f"{__name__}.api")     # not `from baseparams import api`: it asks here
        return api if name == "api" else getattr(api, name)
    raise AttributeError(f"module 'baseparams' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(API))


class _CallablePackage(types.ModuleType):
    """``baseparams.identify``, ``baseparams.diagnose`` and ``baseparams.excite`` are subpackages (their modules keep
    their dotted names) and, called, the API functions of the same name: importing a
    submodule binds the package to the attribute, so ``bp.identify(...)`` must work on it."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        from baseparams import api
        return getattr(api, self.__name__.rpartition(".")[2])(*args, **kwargs)


def _callable_packages() -> None:
    # the packages' __init__ import nothing (their public names load on first use): importing
    # them here costs nothing
    import importlib
    for name in ("identify", "diagnose", "excite"):
        importlib.import_module(f"{__name__}.{name}").__class__ = _CallablePackage


if not TYPE_CHECKING:
    _callable_packages()
