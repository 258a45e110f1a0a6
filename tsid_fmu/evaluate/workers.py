"""Local worker processes that run parameter sets and survive the FMU's native code.

:class:`LocalPool` starts worker processes; each builds one
:class:`~tsid_fmu.evaluate.runner.SetRunner` when it starts (extracts the FMU,
instantiates it once) and reuses it for every job. One job is one parameter set.

* A worker that dies (``abort()``, segmentation fault, ``exit()``) is replaced, and the
  set it was running is run once more, in a worker that has run nothing else (a crash
  can be the worker's state, not the parameters'). A set that crashes that worker too
  fails -- ``inf`` costs, reason ``"<experiment>: worker crashed (signal 11 SIGSEGV);
  the worker was replaced (on the retry in a fresh worker; first attempt: ...)"``, both
  attempts named -- and one that succeeds there is noted in :attr:`LocalPool.retried`.
  Either way the set's costs and count are those of its last attempt alone. The jobs
  queued behind it go to other workers.
* A simulation that runs past the :class:`~tsid_fmu.evaluate.timelimit.TimeLimit` is
  stopped: its worker is killed and replaced, and the set fails with the reason.
* With ``recycle_after``, a worker is replaced after that many jobs (FMUs that leak).

Each worker publishes, in a few words of shared memory, which job and which simulation
it is running and since when; that is how the parent applies the limit to each
simulation (not to a whole job), and how it knows, after a crash, which experiment was
running and how many simulations the set had started -- the same count a run that did
not crash would have reported up to there.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
import warnings
from collections import deque
from multiprocessing.connection import Connection, wait
from typing import Any

from tsid_fmu.errors import FMUError
from tsid_fmu.evaluate.processes import (
    children_allowed,
    error_reason,
    exit_reason,
    main_module_hidden,
    portable_error,
    worker_context,
)
from tsid_fmu.evaluate.runner import (
    Job,
    OnResult,
    SetResult,
    SetRunner,
    SimResult,
    failed_result,
    warm_up,
)
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.evaluate.timelimit import TimeLimit

__all__ = ["LocalPool", "children_allowed", "exit_reason"]

SHUTDOWN_GRACE = 2.0  # seconds a worker gets to close its FMU before it is killed
PREFETCH = 2  # jobs in flight per worker, so it never waits for the parent between jobs
# shared state of a worker: job sequence number, simulations started, experiment,
# replicate, time.monotonic() at the start of the running simulation (0: none running)
_SEQ, _STARTED, _EXP, _REP, _SINCE = range(5)


class _SharedMonitor:
    """Writes what the worker is simulating into memory its parent can read."""

    def __init__(self, state: Any) -> None:
        self.state = state

    def begin(self, seq: int) -> None:
        s = self.state
        s[_SINCE] = 0.0
        s[_STARTED] = 0.0
        s[_SEQ] = float(seq)

    def started(self, experiment: int, replicate: int, count: int) -> None:
        s = self.state
        s[_EXP], s[_REP], s[_STARTED] = experiment, replicate, count
        s[_SINCE] = time.monotonic()

    def finished(self) -> None:
        self.state[_SINCE] = 0.0

    def where(self) -> tuple[int, int] | None:
        s = self.state
        return (int(s[_EXP]), int(s[_REP])) if s[_STARTED] > 0 else None


def _worker_main(conn: Connection, spec: EvaluationSpec, state: Any, scratch: str) -> None:
    """Entry point of a worker process: build the runner, then run jobs until told to stop.

    ``scratch`` is the worker's own temporary folder (its FMU extractions go there); the
    parent removes it once the process has ended, however it ended.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business
    tempfile.tempdir = scratch
    monitor = _SharedMonitor(state)
    try:
        runner = SetRunner(spec, monitor)
        warm_up()  # load the compiled loop now, not in the first (timed) simulation
    except BaseException as exc:
        conn.send(("init_error", portable_error(exc)))
        return
    conn.send(("ready", os.getpid()))
    try:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                return
            if msg[0] != "job":
                return  # "stop"
            _, seq, *job = msg
            monitor.begin(seq)
            result: SetResult | SimResult
            try:
                result = runner.run_job(tuple(job))  # type: ignore[arg-type]
            except Exception as exc:  # never lose the reason of a failed set
                where = monitor.where()
                result = failed_result(
                    spec, job[0], error_reason(exc), nfev=runner.started, where=where
                )
            conn.send(("done", seq, result))
    finally:
        runner.close()


class _Worker:
    """One worker process, its shared state and its jobs in flight (the first is running)."""

    def __init__(self, ctx: Any, spec: EvaluationSpec, number: int) -> None:
        self.conn, child = ctx.Pipe()
        self.state = ctx.RawArray("d", 5)
        self.scratch = tempfile.mkdtemp(prefix="tsid-worker-")
        self.process = ctx.Process(
            target=_worker_main,
            args=(child, spec, self.state, self.scratch),
            name=f"tsid-worker-{number}",
            daemon=True,
        )
        with main_module_hidden():
            self.process.start()
        child.close()
        self.ready = False
        self.inflight: deque[tuple[int, int]] = deque()  # (sequence number, job index)
        self.sent = 0

    def send(self, seq: int, index: int, job: Job) -> None:
        self.conn.send(("job", seq, *job))
        self.inflight.append((seq, index))
        self.sent += 1

    def running(self) -> tuple[int, float]:
        """Return ``(simulations started, start time)`` of the running job's simulation."""
        if not self.begun():
            return 0, 0.0
        return int(self.state[_STARTED]), float(self.state[_SINCE])

    def begun(self) -> bool:
        """Return True if the oldest job in flight has started."""
        return bool(self.inflight) and int(self.state[_SEQ]) == self.inflight[0][0]

    def where(self) -> tuple[int, int] | None:
        started, _ = self.running()
        return (int(self.state[_EXP]), int(self.state[_REP])) if started else None

    def kill(self) -> None:
        """End the process now (if it still runs) and remove its temporary folder."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.conn.close()
        shutil.rmtree(self.scratch, ignore_errors=True)

    def stop(self) -> None:
        try:
            self.conn.send(("stop",))
        except (OSError, EOFError, BrokenPipeError):
            pass
        self.process.join(SHUTDOWN_GRACE)
        self.kill()


class LocalPool:
    """Worker processes that run jobs, survive crashes and apply a time limit.

    Parameters
    ----------
    spec : EvaluationSpec
        What the workers simulate.
    n_workers : int
        Processes to start.
    limit : TimeLimit
        Per-simulation time limit.
    recycle_after : int, optional
        Replace a worker after this many jobs.
    start_method : {"forkserver", "spawn"}, optional
        Default ``forkserver`` where available (a fork of a small server process that
        has imported tsid-fmu, never of the calling process), else ``spawn``.

    Raises
    ------
    TsidError
        A worker's start-up error (the FMU cannot be opened...), as the serial
        evaluator would raise it.
    """

    def __init__(
        self,
        spec: EvaluationSpec,
        n_workers: int,
        limit: TimeLimit,
        recycle_after: int | None = None,
        start_method: str | None = None,
    ) -> None:
        self.ctx = worker_context(start_method)
        self.spec = spec
        self.limit = limit
        self.recycle_after = recycle_after
        self._count = 0
        self._seq = 0
        self._retries: deque[int] = deque()  # crashed jobs of this call, for a fresh worker
        self._first: dict[int, str] = {}  # job index -> why its first attempt failed
        self.retried: list[str] = []  # crashed jobs that a fresh worker then ran through
        self.n_workers = n_workers
        self.workers: list[_Worker] = []
        for _ in range(n_workers):
            self._spawn()
        self._wait_ready()

    def _spawn(self) -> _Worker:
        self._count += 1
        w = _Worker(self.ctx, self.spec, self._count)
        self.workers.append(w)
        return w

    def _wait_ready(self) -> None:
        """Block until every starting worker is ready; raise its start-up error."""
        while True:
            starting = [w for w in self.workers if not w.ready]
            if not starting:
                return
            wait([w.conn for w in starting] + [w.process.sentinel for w in starting])
            for w in starting:
                self._handle_startup(w, raise_errors=True)

    def _handle_startup(self, w: _Worker, raise_errors: bool) -> None:
        msg: Any = None
        if w.conn.poll():
            try:
                msg = w.conn.recv()
            except (EOFError, OSError):
                msg = None
        elif w.process.is_alive():
            return
        if msg is not None and msg[0] == "ready":
            w.ready = True
            return
        self.workers.remove(w)
        w.kill()
        error = (
            msg[1]
            if msg is not None
            else FMUError(
                f"{self.spec.fmu.name}: a worker process failed to start "
                f"({exit_reason(w.process.exitcode)})"
            )
        )
        if raise_errors:
            self.close()
            raise error
        warnings.warn(f"tsid_fmu.evaluate: replacement worker failed: {error}", stacklevel=3)

    def _replace(self, w: _Worker) -> None:
        if w in self.workers:
            self.workers.remove(w)
        w.kill()
        self._spawn()

    def run(self, jobs: list[Job], on_result: OnResult) -> None:
        """Run ``jobs``; call ``on_result(index, SetResult or SimResult)`` for each.

        Never raises for a job: a crash or time-out gives that job a failed result. When
        the caller is interrupted (Ctrl-C), the workers that still hold jobs of this call
        are replaced, so that no late reply reaches a later call.
        """
        pending: deque[int] = deque(range(len(jobs)))
        self._retries.clear()
        self._first.clear()
        while len(self.workers) < self.n_workers:  # replacements after an interruption
            self._spawn()
        try:
            while pending or self._retries or any(w.inflight for w in self.workers):
                self._dispatch(pending, jobs)
                if not self.workers:
                    for i in [*self._retries, *pending]:
                        reason = "no worker process is left"
                        on_result(i, failed_result(self.spec, jobs[i][0], reason))
                    return
                busy = [w for w in self.workers if w.inflight or not w.ready]
                ready = wait(
                    [w.conn for w in busy] + [w.process.sentinel for w in busy],
                    timeout=self._wait_time(busy),
                )
                for w in busy:
                    self._service(w, ready, pending, jobs, on_result)
        except BaseException:
            # the workers still busy with this call's jobs stop (after their current
            # simulation, or are killed after a grace period) so that no late reply
            # reaches a later call; the next call starts their replacements
            busy = [w for w in self.workers if w.inflight]
            self.workers = [w for w in self.workers if not w.inflight]
            _stop_all(busy)
            raise

    def _dispatch(self, pending: deque[int], jobs: list[Job]) -> None:
        quota = self.recycle_after
        n_ready = sum(w.ready for w in self.workers)
        for w in list(self.workers):  # a crashed job's retry: a worker that ran nothing
            if self._retries and w.ready and not w.sent:
                self._seq += 1
                index = self._retries.popleft()
                try:
                    w.send(self._seq, index, jobs[index])
                except (OSError, BrokenPipeError):
                    self._retries.appendleft(index)
                    self._replace(w)
        for w in list(self.workers):
            while (
                w.ready
                and pending
                # a job queued behind another only while there is enough for every
                # worker, so that none sits idle at the end while another has two
                and len(w.inflight) < (PREFETCH if len(pending) > n_ready else 1)
                and (quota is None or w.sent < quota)
            ):
                index = pending.popleft()
                self._seq += 1
                try:
                    w.send(self._seq, index, jobs[index])
                except (OSError, BrokenPipeError):  # it died: the job goes elsewhere
                    pending.appendleft(index)
                    if not w.inflight:  # else its sentinel tells the rest
                        self._replace(w)
                    break

    def _wait_time(self, busy: list[_Worker]) -> float | None:
        """Seconds until the earliest simulation can pass the limit (None: no limit)."""
        limit = self.limit.seconds()
        if limit is None:
            return None
        now = time.monotonic()
        end = now + limit  # a worker not in a simulation now cannot pass it before that
        for w in busy:
            _, since = w.running()
            if w.ready and since > 0:
                end = min(end, since + limit)
        return max(end - now, 0.0) + 0.01

    def _service(
        self,
        w: _Worker,
        ready: list[Any],
        pending: deque[int],
        jobs: list[Job],
        on_result: OnResult,
    ) -> None:
        if not w.ready:
            if w.conn in ready or w.process.sentinel in ready:
                self._handle_startup(w, raise_errors=False)
            return
        while w.inflight and w.conn.poll():
            try:
                reply = w.conn.recv()
            except (EOFError, OSError):
                break
            _seq, index = w.inflight.popleft()
            limit = self.limit.seconds()
            longest = max(reply[2].durations, default=0.0)
            if limit is not None and longest > limit and getattr(reply[2], "error", None) is None:
                # it finished before the next check: past the limit all the same, as a
                # simulation killed at the limit (the same rule whatever the timing)
                reason = f"{self.limit.exceeded()} (it took {longest:.3g} s)"
                done = failed_result(self.spec, jobs[index][0], reason, nfev=reply[2].nfev)
                reply = (*reply[:2], done)
            self.limit.observe(reply[2].durations)
            if index in self._first and getattr(reply[2], "error", None) is None:
                self.retried.append(
                    f"{_describe(jobs[index])}: {self._first[index]}; the retry in a fresh "
                    "worker succeeded"
                )
            on_result(index, reply[2])
        quota = self.recycle_after
        if not w.inflight and quota is not None and w.sent >= quota:
            self.workers.remove(w)  # recycle: a fresh process for the next jobs
            w.stop()
            self._spawn()
            return
        if not w.inflight:
            return
        dead = w.process.sentinel in ready or not w.process.is_alive()
        limit = self.limit.seconds()
        _, since = w.running()
        if dead or (limit is not None and since > 0 and time.monotonic() - since > limit):
            self._fail_running(w, dead, pending, jobs, on_result)

    def _fail_running(
        self,
        w: _Worker,
        dead: bool,
        pending: deque[int],
        jobs: list[Job],
        on_result: OnResult,
    ) -> None:
        """Fail the job ``w`` is running, requeue the ones behind it, replace ``w``."""
        if dead:
            w.process.join(5)
            reason = f"{exit_reason(w.process.exitcode)}; the worker was replaced"
        else:
            reason = f"{self.limit.exceeded()}; the worker was killed and replaced"
        started, _ = w.running()
        where = w.where()
        begun = w.begun()
        pending.extendleft(i for _, i in reversed(w.inflight))  # run them elsewhere, next
        w.inflight.clear()
        self._replace(w)
        if not begun:  # it died between jobs (killed from outside): nothing was lost
            return
        index = pending.popleft()
        if dead and index not in self._first:
            # a crash may be the worker's, not the parameters': once more, in a fresh one
            self._first[index] = reason
            self._retries.append(index)
            return
        if index in self._first:
            reason = (
                f"{reason} (on the retry in a fresh worker; first attempt: {self._first[index]})"
            )
        on_result(
            index, failed_result(self.spec, jobs[index][0], reason, nfev=started, where=where)
        )

    def close(self) -> None:
        """Stop the workers (they free their FMU instances and extracted folders)."""
        workers, self.workers = self.workers, []
        _stop_all(workers)


def _describe(job: Job) -> str:
    """Return the parameter set of a job, for a note (``"gain=1.5, bias=0"``)."""
    return ", ".join(f"{k}={v:.6g}" for k, v in job[1].items())


def _stop_all(workers: list[_Worker]) -> None:
    """Tell ``workers`` to stop; kill those not gone after ``SHUTDOWN_GRACE`` seconds."""
    for w in workers:
        try:
            w.conn.send(("stop",))
        except (OSError, EOFError, BrokenPipeError):
            pass
    deadline = time.monotonic() + SHUTDOWN_GRACE
    for w in workers:
        w.process.join(max(deadline - time.monotonic(), 0.0))
        w.kill()
