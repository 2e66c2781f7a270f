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

from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

API = ("load", "solve", "validate", "simulate", "identify", "diagnose", "export", "convert", "excite")
__all__ = ["__version__", *API]

if TYPE_CHECKING:
    from baseparams.api import convert, diagnose, excite, export, identify, load, simulate, solve, validate


def __getattr__(name: str) -> Any:
    """The API functions, imported from :mod:`baseparams.api` on first use."""
    if name in API:
        from baseparams import api
        return getattr(api, name)
    raise AttributeError(f"module 'baseparams' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(API))
