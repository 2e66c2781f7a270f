"""Run jobs: here, in local worker processes, or on a Dask cluster.

Every runner returns one :class:`~baseparams.orchestrate.jobs.Outcome` per job, in job
order, whatever happens to the job: a job that raises, dies (its process killed or
crashed) or passes its timeout is reported as such and the other jobs go on.

- :class:`InProcess` (the default): one job after the other in this process; a timeout
  through SIGALRM (POSIX, main thread; elsewhere no timeout).
- :class:`Processes`: up to N jobs at a time, each in its own process (forked on Linux),
  so a crash or a hang costs only that job: the parent kills it at the timeout.
- :class:`DaskCluster`: jobs on an existing Dask scheduler (``tcp://host:8786``) or on a
  ``LocalCluster`` started for the run; at most as many jobs in flight as the cluster
  has worker threads, so a job's timeout counts from when a worker can start it. A job
  past its timeout is cancelled; Dask cannot stop a running task, so its thread runs on
  until it ends (Dask needs the optional extra ``baseparams[distributed]``). Every wait
  on the cluster has a deadline: an address that is no Dask scheduler is an input
  error within seconds, and a cluster left without workers or scheduler ends the run
  with each unfinished job reported ``lost``.

Worker processes of :class:`Processes` die with their parent, however it ends
(:func:`die_with_parent`), and leave Ctrl-C to it.
"""

import contextlib
import ctypes
import multiprocessing
import os
import re
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

from baseparams.errors import InputError
from baseparams.orchestrate.jobs import DIED, INTERNAL, LOST, TIMEOUT, AnyJob, Job, Outcome, run_job

Progress = Callable[[int, int, str], None]      # (done, total, label of the job just done)
POLL_S = 0.05


class JobTimeout(BaseException):
    """Raised by SIGALRM inside an in-process job (BaseException: solvers catch Exception)."""


class Runner(Protocol):
    def run(self, jobs: Sequence[AnyJob], timeout: float | None = None,
            progress: Progress | None = None) -> list[Outcome]: ...


class InProcess:
    """One job after the other, in this process."""
    workers = 1

    def run(self, jobs: Sequence[AnyJob], timeout: float | None = None, progress: Progress | None = None) -> list[Outcome]:
        outcomes = []
        for k, job in enumerate(jobs):
            outcomes.append(_run_with_alarm(job, timeout))
            if progress:
                progress(k + 1, len(jobs), job.label)
        return outcomes


def _run_with_alarm(job: AnyJob, timeout: float | None) -> Outcome:
    usable = timeout and hasattr(signal, "SIGALRM") and threading.current_thread() is threading.main_thread()
    if not usable or timeout is None:
        return run_job(job)

    def expire(signum: int, frame: Any) -> None:
        raise JobTimeout()

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    start = time.perf_counter()
    try:
        return run_job(job)
    except JobTimeout:
        return Outcome(job.mechanism.name, job.solver, TIMEOUT, time.perf_counter() - start,
                       message=f"no result within {timeout:g} s")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


class _Window:
    """Up to ``size`` jobs in flight through ``start``/``poll``/``stop`` callables; timeouts
    counted from each job's start."""

    def __init__(self, size: int, start: Callable[[AnyJob], Any], poll: Callable[[Any, AnyJob], Outcome | None],
                 stop: Callable[[Any], None], health: Callable[[], str | None] | None = None) -> None:
        self.size, self.start, self.poll, self.stop = max(1, size), start, poll, stop
        self.health = health        # None while jobs can run, else why every unfinished job is lost

    def run(self, jobs: Sequence[AnyJob], timeout: float | None = None, progress: Progress | None = None) -> list[Outcome]:
        outcomes: list[Outcome | None] = [None] * len(jobs)
        waiting = list(range(len(jobs)))
        running: dict[int, tuple[Any, float]] = {}
        done = 0
        try:
            while waiting or running:
                while waiting and len(running) < self.size:
                    k = waiting.pop(0)
                    running[k] = (self.start(jobs[k]), time.perf_counter())
                for k, (handle, began) in list(running.items()):
                    outcome = self.poll(handle, jobs[k])
                    elapsed = time.perf_counter() - began
                    if outcome is None and timeout and elapsed > timeout:
                        self.stop(handle)
                        outcome = Outcome(jobs[k].mechanism.name, jobs[k].solver, TIMEOUT, elapsed,
                                          message=f"no result within {timeout:g} s")
                    if outcome is not None:
                        outcomes[k] = outcome
                        del running[k]
                        done += 1
                        if progress:
                            progress(done, len(jobs), jobs[k].label)
                reason = self.health() if self.health and (waiting or running) else None
                if reason is not None:
                    for k, (handle, began) in list(running.items()):
                        self.stop(handle)
                        outcomes[k] = Outcome(jobs[k].mechanism.name, jobs[k].solver, LOST,
                                              time.perf_counter() - began, message=f"{reason}, while the job ran")
                        del running[k]
                    for k in waiting:
                        outcomes[k] = Outcome(jobs[k].mechanism.name, jobs[k].solver, LOST, 0.0,
                                              message=f"{reason}; the job never started")
                    done += len(waiting)
                    waiting = []
                    if progress:
                        progress(len(jobs), len(jobs), "lost")
                    break
                time.sleep(POLL_S)
        finally:
            for handle, _ in running.values():
                self.stop(handle)
        return [o for o in outcomes if o is not None]     # every job got one (lost: LOST)


PR_SET_PDEATHSIG = 1        # linux/prctl.h
WATCHDOG_S = 0.5            # how often a worker checks that its parent still lives (no prctl)


def die_with_parent(parent: int) -> None:
    """Make this worker process end when ``parent`` does, however the parent ends.

    A parent killed by SIGKILL runs no cleanup, so the worker must notice by itself: on
    Linux the kernel sends it SIGKILL (``prctl(PR_SET_PDEATHSIG)``); elsewhere, and as a
    second line, a daemon thread polls ``os.getppid()``. The worker also leaves the
    terminal's process group and ignores SIGINT: Ctrl-C is the parent's to handle (it
    kills its workers and prints one line), not one KeyboardInterrupt traceback per worker.
    """
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(os, "setpgid"):
        try:
            os.setpgid(0, 0)
        except OSError:
            pass
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:          # the parent died before the request took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(WATCHDOG_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="baseparams-watchdog", daemon=True).start()


def _child(job: AnyJob, connection: Any, parent: int | None = None) -> None:
    die_with_parent(parent if parent is not None else os.getppid())
    connection.send(run_job(job))
    connection.close()


class Processes:
    """Each job in its own process, ``workers`` at a time."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        methods = multiprocessing.get_all_start_methods()
        self.context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")

    def run(self, jobs: Sequence[AnyJob], timeout: float | None = None, progress: Progress | None = None) -> list[Outcome]:
        return _Window(self.workers, self._start, self._poll, self._stop).run(jobs, timeout, progress)

    def _start(self, job: AnyJob) -> Any:
        receive, send = self.context.Pipe(duplex=False)
        process = self.context.Process(target=_child, args=(job, send, os.getpid()), daemon=True)  # type: ignore[attr-defined]
        process.start()
        if hasattr(os, "setpgid"):      # also here: no window where the terminal's Ctrl-C reaches it
            try:
                os.setpgid(process.pid, process.pid)
            except OSError:
                pass
        send.close()
        return process, receive, time.perf_counter()

    @staticmethod
    def _poll(handle: Any, job: AnyJob) -> Outcome | None:
        process, receive, began = handle
        if receive.poll():
            try:
                outcome = receive.recv()
            except EOFError:
                outcome = None
            process.join()
            if outcome is not None:
                return outcome
        if process.is_alive():
            return None
        process.join()
        return Outcome(job.mechanism.name, job.solver, DIED, time.perf_counter() - began,
                       message=f"the worker process died (exit code {process.exitcode})")

    @staticmethod
    def _stop(handle: Any) -> None:
        process, receive, _ = handle
        if process.is_alive():
            process.kill()
        process.join()
        receive.close()


DASK_SCHEMES = ("tcp", "tls", "ucx", "inproc", "ws", "wss")
CONNECT_S = 15.0            # to reach a scheduler and complete Dask's handshake
RPC_S = 10.0                # one call to the scheduler
HEALTH_RPC_S = 5.0          # the health check's call (a silent scheduler counts as trouble after it)
LOST_AFTER_S = 20.0         # no worker, or no scheduler, this long: the jobs in flight are lost
HEALTH_EVERY_S = 1.0


def check_scheduler_address(address: str) -> tuple[str, str, int | None]:
    """(scheme, host, port) of a Dask scheduler address (``tcp://host:8786``, ``host:8786``),
    or an InputError (exit 2) naming ``--scheduler``: a typo is bad input, not a hang or
    an internal error."""
    text = address.strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    match = re.fullmatch(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(?::([0-9]{1,5}))?", rest)
    port = int(match[2]) if match and match[2] else None
    if scheme not in DASK_SCHEMES or match is None or (port is not None and not 0 < port < 65536) \
            or (scheme != "inproc" and port is None):
        raise InputError(f"{address!r} is not a Dask scheduler address: give tcp://HOST:PORT (e.g. "
                         f"tcp://127.0.0.1:8786) or 'local'", key="--scheduler")
    return scheme, match[1].strip("[]"), port


def _bounded(call: Callable[[], Any], seconds: float) -> Any:
    """``call()`` with a deadline: its value or exception, or TimeoutError after ``seconds``.

    Some Dask calls wait forever on a peer that accepts a connection and never answers (a
    silent listener, an HTTP server), whatever their own timeout says; the call runs in a
    daemon thread that is abandoned at the deadline (it cannot hold the process open)."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = call()
        except BaseException as exc:        # handed to the caller
            box["error"] = exc

    thread = threading.Thread(target=run, name="baseparams-dask-call", daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        raise TimeoutError(f"no answer within {seconds:g} s")
    if "error" in box:
        raise box["error"]
    return box.get("value")


class DaskCluster:
    """Jobs on a Dask cluster: ``address`` of a running scheduler, or "local" for a
    LocalCluster of ``workers`` single-threaded worker processes started for the run.

    Every wait has a deadline: connecting (``connect_s``, then an InputError: the address
    is not a usable Dask scheduler), each call to the scheduler (RPC_S), and the cluster's
    health: with no worker, or no reachable scheduler, for ``lost_after_s``, every job not
    yet finished is reported as ``lost`` (by name) and the run ends.
    """

    def __init__(self, address: str, workers: int | None = None, connect_s: float = CONNECT_S,
                 lost_after_s: float = LOST_AFTER_S) -> None:
        self.cluster = None
        self.lost_after_s = lost_after_s
        if address != "local":
            scheme, host, port = check_scheduler_address(address)
            if scheme == "tcp" and port is not None:        # tcp always has one (checked above)
                _probe(address, host, port, min(connect_s, 5.0))
        try:
            from dask.distributed import Client, LocalCluster     # optional extra: imported on use
        except ImportError:
            raise InputError("--scheduler needs Dask: pip install 'baseparams[distributed]'") from None
        self._log_level = _quiet_dask_logs()
        if address == "local":
            # the workers inherit both: Ctrl-C is this process's to handle, and their log lines
            # (a task cancelled when the run stops, a heartbeat to a scheduler closing under them)
            # are not the user's to read: the runner reports every job's outcome
            try:
                with _sigint_deferred() as received, _environment(DASK_LOGGING__DISTRIBUTED="critical"):
                    # no dashboard, and the scheduler's HTTP server on any free port: on its default
                    # (8787, taken by another cluster or a notebook's) Dask warned on stderr
                    self.cluster = LocalCluster(n_workers=workers or 2, threads_per_worker=1, processes=True,
                                                dashboard_address=None,
                                                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
                if received:
                    raise KeyboardInterrupt
            except KeyboardInterrupt:
                self._close_cluster()           # Ctrl-C while it started: its processes go too
                _restore_dask_logs(self._log_level)
                raise
            address = self.cluster.scheduler_address
        try:
            self.client = _bounded(lambda: Client(address, timeout=f"{connect_s}s"), connect_s + 2)
            nthreads = _bounded(self.client.nthreads, RPC_S)
        except (OSError, TimeoutError) as exc:
            self._close_cluster()
            _restore_dask_logs(self._log_level)
            raise InputError(f"no Dask scheduler answered at {address} ({exc}): is it the address of a "
                             f"running Dask scheduler?", key="--scheduler") from None
        except KeyboardInterrupt:
            self._close_cluster()               # Ctrl-C while connecting: the cluster started here goes
            _restore_dask_logs(self._log_level)
            raise
        except Exception as exc:      # noqa: BLE001 -- any answer no scheduler gives (issue 46)
            # a peer that answers garbage: Dask read a frame length of 3.07 EiB (MemoryError), a
            # dimension (ValueError), ... -- not a scheduler, whatever the error it provoked
            self._close_cluster()
            _restore_dask_logs(self._log_level)
            raise InputError(f"no Dask scheduler answered at {address}: the peer's answer is not Dask's "
                             f"({type(exc).__name__}: {str(exc)[:120]}): is it the address of a running Dask "
                             f"scheduler?", key="--scheduler") from None
        self.workers = max(1, sum(nthreads.values()))
        self._checked = 0.0
        self._trouble_since: float | None = None

    def run(self, jobs: Sequence[AnyJob], timeout: float | None = None, progress: Progress | None = None) -> list[Outcome]:
        try:
            return _Window(self.workers, self._start, self._poll, self._stop, self._health).run(
                jobs, timeout, progress)
        finally:
            self.close()

    def _start(self, job: AnyJob) -> Any:
        try:
            return self.client.submit(run_job, job, pure=False), time.perf_counter()
        except Exception as exc:             # a closed client: the scheduler is gone
            return _Failed(f"{type(exc).__name__}: {exc}"), time.perf_counter()

    @staticmethod
    def _poll(handle: Any, job: AnyJob) -> Outcome | None:
        future, began = handle
        if isinstance(future, _Failed):
            return Outcome(job.mechanism.name, job.solver, LOST, time.perf_counter() - began,
                           message=f"not submitted: {future.reason}")
        if not future.done():
            return None
        try:
            return future.result(timeout=RPC_S)
        except Exception as exc:          # the worker died, the scheduler went, or unpicklable
            name = type(exc).__name__
            status = DIED if "Killed" in name else LOST if _is_lost(exc) else INTERNAL
            return Outcome(job.mechanism.name, job.solver, status, time.perf_counter() - began,
                           message=f"{name}: {exc}")

    @staticmethod
    def _stop(handle: Any) -> None:
        future = handle[0]
        if not isinstance(future, _Failed):
            try:
                future.cancel()
            except Exception:
                pass

    def _health(self) -> str | None:
        """None while the cluster can run jobs; the reason once it has had no worker, or no
        reachable scheduler, for ``lost_after_s``."""
        now = time.monotonic()
        if now - self._checked < HEALTH_EVERY_S:
            return None
        trouble = None
        if getattr(self.client, "status", "running") not in ("running", "connecting", "newly-created"):
            # Dask has given up reconnecting already: no reason to wait any longer
            return f"the Dask scheduler is gone (the client is {self.client.status})"
        else:
            try:
                if not _bounded(self.client.nthreads, HEALTH_RPC_S):
                    trouble = "the cluster has no worker"
            except Exception as exc:
                trouble = f"the scheduler does not answer ({type(exc).__name__}: {exc})"
        self._checked = time.monotonic()
        if trouble is None:
            self._trouble_since = None
            return None
        if self._trouble_since is None:
            self._trouble_since = now           # when the failed check began
        if self._checked - self._trouble_since >= self.lost_after_s:
            return f"{trouble} for {self.lost_after_s:g} s"
        return None

    def close(self) -> None:
        """Close the client and a cluster started here; a Ctrl-C meanwhile is acted on once both
        are closed (an interrupted close left the cluster to Dask's exit hook, which printed the
        workers' tracebacks after ``interrupted``)."""
        with _sigint_deferred(inherit=False) as received:
            try:
                _bounded(lambda: self.client.close(timeout=5), 10)
            except Exception:
                pass                              # a scheduler already gone: nothing to close
            self._close_cluster()
            _restore_dask_logs(self._log_level)
        if received:
            raise KeyboardInterrupt

    def _close_cluster(self) -> None:
        cluster = self.cluster
        if cluster is not None:
            try:
                _bounded(lambda: cluster.close(timeout=10), 15)
            except Exception:
                pass


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while worker processes are started: a disposition of SIG_IGN survives
    fork and exec, and Python then installs no KeyboardInterrupt handler in the child, so
    Ctrl-C in the terminal no longer prints a traceback from each Dask worker."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _quiet_dask_logs() -> int:
    """Dask's own log lines below ERROR silenced in this process while a cluster is in use;
    the level before, for :func:`_restore_dask_logs`. Why (issue 46): on Ctrl-C the nannies'
    "Worker process still alive after 4.0 seconds, killing" and the workers' "ended with
    CancelledError" warnings printed before ``interrupted``; the runner reports every job's
    outcome itself."""
    import logging
    logger = logging.getLogger("distributed")
    level = logger.level
    if logger.getEffectiveLevel() < logging.ERROR:
        logger.setLevel(logging.ERROR)
    return level


def _restore_dask_logs(level: int) -> None:
    import logging
    logging.getLogger("distributed").setLevel(level)


@contextlib.contextmanager
def _environment(**values: str) -> Iterator[None]:
    """Environment variables set while worker processes are started (they inherit them), and
    the previous values back afterwards; a value the user set is kept."""
    previous = {name: os.environ.get(name) for name in values}
    for name, value in values.items():
        os.environ.setdefault(name, value)
    try:
        yield
    finally:
        for name, old in previous.items():
            if old is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = old


@contextlib.contextmanager
def _sigint_deferred(inherit: bool = True) -> Iterator[list[int]]:
    """SIGINT blocked in this thread while worker processes are started, and recorded (the
    list yielded) rather than lost: the workers inherit the blocked mask (fork and exec keep
    it), so Ctrl-C in the terminal reaches none of them, and a Ctrl-C meanwhile is acted on
    once they are up (the caller stops them and raises KeyboardInterrupt). Why (issue 46):
    with SIGINT ignored (:func:`_sigint_ignored`) a Ctrl-C during the cluster's start was lost
    and the run went on to exit 0. Elsewhere than the main thread, or without
    ``pthread_sigmask``: :func:`_sigint_ignored` when processes start (``inherit``), else
    nothing is deferred."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        with _sigint_ignored() if inherit else contextlib.nullcontext():
            yield []
        return
    received: list[int] = []

    def record(signum: int, frame: Any) -> None:
        received.append(signum)

    previous = signal.signal(signal.SIGINT, record)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield received
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})     # one pending: recorded now
        signal.signal(signal.SIGINT, previous)


class _Failed:
    """A job that could not be submitted (its reason is reported as the job's outcome)."""

    def __init__(self, reason: str) -> None:
        self.reason = reason


def _is_lost(exc: BaseException) -> bool:
    names = {t.__name__ for t in type(exc).__mro__}
    return bool(names & {"CancelledError", "ClosedClientError", "CommClosedError", "FutureCancelledError",
                         "TimeoutError", "OSError", "ConnectionError"})


def _probe(address: str, host: str, port: int, seconds: float) -> None:
    """A TCP connection to the scheduler's port, refused or unroutable in a few seconds
    rather than after Dask's retries (an InputError naming the address)."""
    try:
        with socket.create_connection((host, port), timeout=seconds):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise InputError(f"cannot reach the Dask scheduler at {address}: {reason}", key="--scheduler") from None


def make_runner(workers: int | None = None, scheduler: str | None = None) -> Runner:
    """The runner the command line's ``--workers`` and ``--scheduler`` ask for."""
    if scheduler is not None:             # --scheduler "" is a bad address, not "no scheduler"
        return DaskCluster(scheduler, workers)
    if workers and workers > 1:
        return Processes(workers)
    return InProcess()
