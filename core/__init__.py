"""baseparams: base inertial parameters of mechanisms.

The public entry points are the mechanism model (:mod:`baseparams.model.mechanism`), the
loader (:func:`baseparams.io.loader.load_mechanism`), the regressor
(:mod:`baseparams.dynamics.regressor`) and the command line (:mod:`baseparams.cli.commands`).
"""

__version__ = "0.1.0"
