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
  until it ends (Dask needs the optional extra ``baseparams[distributed]``).
"""

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from baseparams.errors import InputError
from baseparams.orchestrate.jobs import DIED, INTERNAL, TIMEOUT, Job, Outcome, run_job

Progress = Callable[[int, int, str], None]      # (done, total, label of the job just done)
POLL_S = 0.05


class JobTimeout(BaseException):
    """Raised by SIGALRM inside an in-process job (BaseException: solvers catch Exception)."""


class Runner(Protocol):
    def run(self, jobs: Sequence[Job], timeout: float | None = None,
            progress: Progress | None = None) -> list[Outcome]: ...


class InProcess:
    """One job after the other, in this process."""
    workers = 1

    def run(self, jobs, timeout=None, progress=None):
        outcomes = []
        for k, job in enumerate(jobs):
            outcomes.append(_run_with_alarm(job, timeout))
            if progress:
                progress(k + 1, len(jobs), job.label)
        return outcomes


def _run_with_alarm(job: Job, timeout: float | None) -> Outcome:
    usable = timeout and hasattr(signal, "SIGALRM") and threading.current_thread() is threading.main_thread()
    if not usable:
        return run_job(job)

    def expire(signum, frame):
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

    def __init__(self, size: int, start: Callable[[Job], Any], poll: Callable[[Any, Job], Outcome | None],
                 stop: Callable[[Any], None]):
        self.size, self.start, self.poll, self.stop = max(1, size), start, poll, stop

    def run(self, jobs, timeout=None, progress=None):
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
                time.sleep(POLL_S)
        finally:
            for handle, _ in running.values():
                self.stop(handle)
        return outcomes


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

    def watch():
        while True:
            time.sleep(WATCHDOG_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="baseparams-watchdog", daemon=True).start()


def _child(job: Job, connection, parent: int | None = None) -> None:
    die_with_parent(parent if parent is not None else os.getppid())
    connection.send(run_job(job))
    connection.close()


class Processes:
    """Each job in its own process, ``workers`` at a time."""

    def __init__(self, workers: int):
        self.workers = workers
        methods = multiprocessing.get_all_start_methods()
        self.context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")

    def run(self, jobs, timeout=None, progress=None):
        return _Window(self.workers, self._start, self._poll, self._stop).run(jobs, timeout, progress)

    def _start(self, job):
        receive, send = self.context.Pipe(duplex=False)
        process = self.context.Process(target=_child, args=(job, send, os.getpid()), daemon=True)
        process.start()
        if hasattr(os, "setpgid"):      # also here: no window where the terminal's Ctrl-C reaches it
            try:
                os.setpgid(process.pid, process.pid)
            except OSError:
                pass
        send.close()
        return process, receive, time.perf_counter()

    @staticmethod
    def _poll(handle, job):
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
    def _stop(handle):
        process, receive, _ = handle
        if process.is_alive():
            process.kill()
        process.join()
        receive.close()


class DaskCluster:
    """Jobs on a Dask cluster: ``address`` of a running scheduler, or "local" for a
    LocalCluster of ``workers`` single-threaded worker processes started for the run."""

    def __init__(self, address: str, workers: int | None = None):
        try:
            from dask.distributed import Client, LocalCluster     # optional extra: imported on use
        except ImportError:
            raise InputError("--scheduler needs Dask: pip install 'baseparams[distributed]'") from None
        self.cluster = None
        if address == "local":
            self.cluster = LocalCluster(n_workers=workers or 2, threads_per_worker=1, processes=True,
                                        dashboard_address=None)
            address = self.cluster.scheduler_address
        try:
            self.client = Client(address, timeout="20s")
        except (OSError, TimeoutError) as exc:
            if self.cluster is not None:
                self.cluster.close()
            raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        self.workers = max(1, sum(self.client.nthreads().values()))

    def run(self, jobs, timeout=None, progress=None):
        try:
            return _Window(self.workers, self._start, self._poll, self._stop).run(jobs, timeout, progress)
        finally:
            self.close()

    def _start(self, job):
        return self.client.submit(run_job, job, pure=False), time.perf_counter()

    @staticmethod
    def _poll(handle, job):
        future, began = handle
        if not future.done():
            return None
        try:
            return future.result()
        except Exception as exc:          # the worker died, or could not unpickle the job
            return Outcome(job.mechanism.name, job.solver, DIED if "Killed" in type(exc).__name__ else INTERNAL,
                           time.perf_counter() - began, message=f"{type(exc).__name__}: {exc}")

    @staticmethod
    def _stop(handle):
        handle[0].cancel()

    def close(self):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_runner(workers: int | None = None, scheduler: str | None = None) -> Runner:
    """The runner the command line's ``--workers`` and ``--scheduler`` ask for."""
    if scheduler:
        return DaskCluster(scheduler, workers)
    if workers and workers > 1:
        return Processes(workers)
    return InProcess()
