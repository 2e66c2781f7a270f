"""The ``baseparams`` command line: verbs (:mod:`.commands`; ``validate`` in :mod:`.validate`), figures (:mod:`.plots`) and
the symbolic derivation report (:mod:`.report`)."""

import os

# The command line's matrices are small (thousands of rows, tens of columns): BLAS threads only
# contend for the cores. With OpenBLAS's default threads diagnose on the TX40 spent more CPU
# than wall time, dp many times its single-thread CPU time (docs/urdf.md). Set before
# numpy is first imported; a user's own setting wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

from . import validate as _validate  # noqa: E402,F401  (registers the verb)
from . import convert as _convert  # noqa: E402,F401  (registers the verb)
from . import identify as _identify  # noqa: E402,F401  (registers simulate and identify)
from . import export as _export  # noqa: E402,F401  (registers the verb)
from . import diagnose as _diagnose  # noqa: E402,F401  (registers the verb)
from . import excite as _excite  # noqa: E402,F401  (registers the verb)
from .commands import main  # noqa: E402

__all__ = ["main"]
