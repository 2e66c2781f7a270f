"""The Python front door: one function per task, each returning the result object the
command line prints (``to_json()``, ``to_text()``, ``to_frame()``, a notebook view).

>>> import baseparams as bp
>>> solution = bp.solve("pendulum", "dp")
>>> solution.rank
3

The functions are re-exported at the package top (``bp.load``, ``bp.solve`` ...); see
docs/api.md. Heavy modules (sympy, flint, scipy, cvxpy) are imported when a function runs.
"""

from .data import diagnose, identify, simulate
from .files import convert, excite, export, validate
from .results import (ChangeDiagnosed, Conversion, Diagnosed, Excitation, Export, Fit, Result, Simulation, Solution,
                      Validation)
from .solving import DEFAULT_SOLVER, get_solver, load, run_solver, solve

__all__ = ["DEFAULT_SOLVER", "load", "solve", "validate", "simulate", "identify", "diagnose", "export",
           "convert", "excite", "get_solver", "run_solver", "Result", "Solution", "Simulation", "Fit",
           "Diagnosed", "ChangeDiagnosed", "Validation", "Excitation", "Export", "Conversion"]
