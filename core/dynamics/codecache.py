"""The generated ball regressor's compiled code kept on disk across processes, as Python keeps
a module's bytecode in ``__pycache__``.

Why: tracing, writing and compiling the straight-line code of a large tree takes about as
long as a whole certified analysis of it (TIAGo's 48 joints: 0.23 s tracing, 0.18 s writing
1.1 MB of source, 0.31 s compiling; issue 47), and it is the same every time the same
mechanism is solved. What is stored is a pure function of its key: the mechanism's content
(every field the tracer can read, as ``repr``), the source of every module of the package
(core, plugins, mechanisms), the Python, sympy, numpy and python-flint versions, and the part
generated. Anything else (a joint type defined by a subclass in another distribution) is not
cached. A file that cannot be read or unpickled is ignored and regenerated; a cache that
cannot be written (read-only home) costs nothing but the saving.

Where: ``$BASEPARAMS_CACHE_DIR`` if set (empty or ``off``: no cache), else
``$XDG_CACHE_HOME/baseparams`` or ``~/.cache/baseparams``; one file per key under
``generated/``, written atomically (several processes may write the same key at once). The
files are code that will be run, as ``__pycache__``'s are: the folder must be writable by its
user alone (the default is; a shared ``BASEPARAMS_CACHE_DIR`` is not a safe choice).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import pickle
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism

FORMAT = 1                # bump when the stored payload's layout changes
FROM_BODIES = 12          # smaller mechanisms generate their code in less time than the key takes
KEEP = 64                 # files kept (the most recently written); older ones are removed
LEFT_OUT = ("path", "source", "title", "description", "warnings")   # fields that do not change the code


def directory() -> Path | None:
    """Where the generated code is kept, or None when the cache is off."""
    chosen = os.environ.get("BASEPARAMS_CACHE_DIR")
    if chosen is not None:
        return None if chosen.strip() in ("", "off") else Path(chosen) / "generated"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "baseparams" / "generated"


@functools.lru_cache(maxsize=1)
def _package_digest() -> str:
    """Every module file of baseparams (path, size and modification time, as Python's own
    bytecode cache checks its sources: 3 ms where reading them all takes 50) and the versions
    the payload depends on."""
    import importlib.util

    import flint
    import numpy
    import sympy
    h = hashlib.sha256(f"{FORMAT} {sys.version} {sympy.__version__} {numpy.__version__} "
                       f"{flint.__version__}".encode())
    for package in ("baseparams", "baseparams.plugins", "baseparams.mechanisms"):     # found, not imported
        spec = importlib.util.find_spec(package)
        for root in (spec.submodule_search_locations or []) if spec is not None else []:
            for path in sorted(Path(root).rglob("*.py")):
                info = path.stat()
                h.update(f"{path}\0{info.st_size}\0{info.st_mtime_ns}\0".encode())
    return h.hexdigest()


def key(mechanism: Mechanism, part: str) -> str | None:
    """The cache key of ``mechanism``'s generated ``part``, or None when it cannot be keyed
    safely (a joint type whose behaviour is not all data of this package)."""
    from baseparams.model.joints import JointType
    if len(mechanism.bodies) < FROM_BODIES or any(type(j.type) is not JointType for j in mechanism.joints):
        return None
    fields = [(f.name, getattr(mechanism, f.name)) for f in dataclasses.fields(mechanism) if f.name not in LEFT_OUT]
    text = repr((part, sorted(mechanism.geometry.items()), fields))
    return hashlib.sha256((_package_digest() + "\0" + text).encode()).hexdigest()


def load(name: str | None) -> Any:
    """The payload stored under ``name``, or None (no cache, no file, or unreadable)."""
    folder = directory()
    if name is None or folder is None:
        return None
    try:
        return pickle.loads((folder / f"{name}.pickle").read_bytes())
    except Exception:                   # missing, truncated by a full disk, another version's: regenerate
        return None


def store(name: str | None, payload: Any) -> None:
    """Keep ``payload`` under ``name`` (atomically); nothing when the cache is off or unwritable."""
    folder = directory()
    if name is None or folder is None:
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, suffix=".tmp", delete=False) as out:
            out.write(pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL))
        os.replace(out.name, folder / f"{name}.pickle")
        _prune(folder)
    except OSError:
        try:
            os.unlink(out.name)
        except (OSError, NameError):
            pass


def _prune(folder: Path) -> None:
    """The KEEP most recently written files kept, the others removed (each source edit or
    upgrade makes new keys; the old files would otherwise pile up)."""
    files = sorted(folder.glob("*.pickle"), key=lambda f: f.stat().st_mtime_ns, reverse=True)
    for old in files[KEEP:]:
        old.unlink(missing_ok=True)
