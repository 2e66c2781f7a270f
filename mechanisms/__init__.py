"""Built-in mechanism files, registered through the ``baseparams_mechanisms`` hook.

Every ``*.toml`` file in this folder is a mechanism; its registry name is the file name
without ``.toml``, which equals the ``mechanism.name`` inside (a test checks it).
"""

from pathlib import Path

from baseparams.hookspecs import hookimpl
from baseparams.registry import MechanismSource

HERE = Path(__file__).resolve().parent


@hookimpl
def baseparams_mechanisms() -> list[MechanismSource]:
    return [MechanismSource(path.stem, path) for path in sorted(HERE.glob("*.toml"))]
