"""Jobs as plain data, and what runs one on a worker.

A job carries the mechanism file's *text*, not a live object, so any worker with the
package and the same plugins installed can run it (a process of this machine or a Dask
worker elsewhere). A worker that lacks a plugin the job needs reports that, as
``status = "missing_plugin"``.
"""

import dataclasses
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, Union

from baseparams import registry
from baseparams.errors import BaseparamsError, InputError
from baseparams.io.loader import load_mechanism
from baseparams.model.mechanism import Mechanism
from baseparams.orchestrate.model_checks import model_checks
from baseparams.solvers.protocol import NotApplicable

MODEL = "model"     # the pseudo-solver name of a mechanism's model checks

# outcome statuses
OK, NOT_APPLICABLE, ERROR, MISSING_PLUGIN, TIMEOUT, DIED, INTERNAL, LOST = (
    "ok", "not_applicable", "error", "missing_plugin", "timeout", "died", "internal_error", "lost")
# LOST: the cluster lost the job (no worker or no scheduler left to run it); DIED: its own
# worker process died while running it


@dataclass(frozen=True)
class MechanismText:
    """A mechanism file as text: its name, the file name (the suffix picks the reader), the
    path it was read from (for messages) and the text itself."""
    name: str
    filename: str
    source: str
    text: str

    @classmethod
    def read(cls, name: str, path: Path) -> "MechanismText":
        return cls(name=name, filename=path.name, source=str(path), text=path.read_text(encoding="utf-8"))


@dataclass(frozen=True)
class Job:
    mechanism: MechanismText
    solver: str                      # a registered solver's name, or MODEL
    options: tuple[tuple[str, Any], ...] = ()      # (name, value) pairs for the solver

    @property
    def label(self) -> str:
        return f"{self.mechanism.name}/{self.solver}"


@dataclass
class Outcome:
    """What came back from one job: JSON-able data only."""
    mechanism: str
    solver: str
    status: str
    seconds: float = 0.0
    result: dict[str, Any] | None = None      # the solver's result JSON, or the model checks
    message: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {"status": self.status, "seconds": round(self.seconds, 3)}
        if self.message:
            out["message"] = self.message
        return out


def load(mechanism: MechanismText) -> Mechanism:
    """The Mechanism in ``mechanism.text``, read by the reader its file name's suffix picks;
    its path (which solvers' messages name) and warnings name the source, not the worker's
    temporary copy, which is gone once it is read."""
    with tempfile.TemporaryDirectory(prefix="baseparams-job-") as folder:
        path = Path(folder) / mechanism.filename
        path.write_text(mechanism.text, encoding="utf-8")
        try:
            loaded = load_mechanism(path)
        except BaseparamsError as exc:
            message = str(getattr(exc, "message", exc)).replace(str(path), mechanism.source)
            raise type(exc)(message) from None
    return dataclasses.replace(loaded, path=mechanism.source,
                               warnings=tuple(w.replace(str(path), mechanism.source) for w in loaded.warnings))


class Executable(Protocol):
    """A job of another kind (``baseparams excite``'s starts): it runs itself."""

    @property
    def mechanism(self) -> MechanismText: ...

    @property
    def solver(self) -> str: ...

    @property
    def label(self) -> str: ...

    def execute(self) -> Outcome: ...


AnyJob = Union[Job, Executable]


def run_job(job: AnyJob) -> Outcome:
    """Run one job here and now; never raises (every failure is an Outcome). A job of another
    kind (``baseparams excite``'s starts) runs itself through its ``execute()``."""
    if not isinstance(job, Job):
        return job.execute()
    start = time.perf_counter()

    def outcome(status: str, result: dict[str, Any] | None = None, message: str = "") -> Outcome:
        return Outcome(job.mechanism.name, job.solver, status, time.perf_counter() - start, result, message)

    try:
        solvers = registry.solvers()
        if job.solver != MODEL and job.solver not in solvers:
            return outcome(MISSING_PLUGIN, message=f"solver {job.solver!r} is not installed on this worker "
                                                    f"(it has: {', '.join(solvers) or 'none'})")
        try:
            mechanism = load(job.mechanism)
        except InputError as exc:
            text = str(getattr(exc, "message", exc))
            status = MISSING_PLUGIN if "unknown joint type" in text else ERROR
            return outcome(status, message=text)
        if job.solver == MODEL:
            return outcome(OK, result={"checks": [c.to_json() for c in model_checks(mechanism)]})
        from baseparams.solvers.run import run_solver        # the one solver sequence
        try:
            result = run_solver(solvers[job.solver].item, mechanism, dict(job.options))
        except NotApplicable as exc:
            return outcome(NOT_APPLICABLE, message=exc.why)
        return outcome(OK, result=result.to_json())
    except BaseparamsError as exc:
        return outcome(ERROR, message=str(getattr(exc, "message", exc)))
    except MemoryError as exc:                  # the machine's limit, not a bug (issue 46)
        from baseparams.dynamics.trajectory import MEMORY_VARIABLE
        return outcome(ERROR, message=f"out of memory: {str(exc).strip() or 'an allocation failed'} (set "
                                      f"{MEMORY_VARIABLE} to the memory the machine has, so that such work is "
                                      "refused with an estimate before it starts)")
    except Exception as exc:                    # a bug in a solver: reported, the run goes on
        return outcome(INTERNAL, message=f"{type(exc).__name__}: {exc}",
                       result={"traceback": traceback.format_exc(limit=8)})
