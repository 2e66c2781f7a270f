"""Experiment design (``baseparams excite``): plan the exciting motion of a mechanism.

:mod:`.fourier` the motion's form, :mod:`.limits` what it must respect, :mod:`.tangent`
forward-mode derivatives of the generated regressor, :mod:`.criterion` the criteria on the
observation matrix with their gradients, :mod:`.design` one optimisation, :mod:`.plan` the
multistart, the verification and the report, :mod:`.plot` the figure (docs/excite.md).
"""
