"""baseparams: base inertial parameters of mechanisms.

The public entry points are the mechanism model (:mod:`baseparams.model`), the
loader (:func:`baseparams.loader.load_mechanism`), the regressor
(:mod:`baseparams.regressor`) and the command line (:mod:`baseparams.cli`).
"""

__version__ = "0.1.0"
