"""Evaluate parameter sets in parallel: local worker processes, or a Dask cluster.

:class:`ParallelEvaluator` has the interface of :class:`tsid_fmu.runner.Evaluator`
(``evaluate``, ``simulate_clean``, ``prepared``, ``n_replicates``, ``nfev``, ``close``)
and runs the rows of an array, times their noise replicates, on several processes. Each
worker builds one :class:`~tsid_fmu.runner.Evaluator` when it starts -- extracts the FMU,
instantiates it once -- and reuses it for every task, so a row's cost is computed by
exactly the serial code on exactly the same inputs: parallel costs are bit-identical to
serial ones, whatever the order the tasks finish in.

One task is one replicate of one parameter set over all experiments. A row's error is
the one the serial run would report (earliest experiment, then earliest replicate).
``nfev`` counts the simulations actually run; for a failed row that can be more than the
serial run, which stops a row at its first failure.

Local workers (the default) also isolate the study from the FMU's native code:

* a worker that dies (``abort()``, segmentation fault, ``exit()``) fails only the
  task it was running -- ``inf`` cost, reason ``"worker crashed (signal 11 SIGSEGV)"``
  -- and is replaced;
* with ``timeout``, a task running longer than ``timeout`` seconds per simulation is
  stopped: the worker is killed and replaced, the row fails with the reason;
* with ``recycle_after``, a worker is replaced after that many tasks (for FMUs that
  leak memory).

Neither ever raises out of :meth:`ParallelEvaluator.evaluate`.

With ``scheduler`` (the address of a ``dask.distributed`` scheduler, or a
``distributed.Client``), tasks go to that cluster instead. The FMU file and the loaded
measured data travel with the tasks, so the workers need only ``tsid-fmu`` installed,
not the study's files. On each Dask worker the FMU runs in a child process of the
worker, so crashes and the time limit are handled there exactly as locally, and a
crashing FMU never takes a Dask worker down. Dask is optional:
``pip install tsid-fmu[dask]``.

Examples
--------
>>> from tsid_fmu.parallel import make_evaluator
>>> with make_evaluator(study, workers=4, timeout=10.0) as ev:   # doctest: +SKIP
...     result = ev.evaluate([{"K_s": 4000.0}, {"K_s": 6000.0}])
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import math
import multiprocessing as mp
import os
import pickle
import signal
import sys
import tempfile
import threading
import time
import types
import warnings
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.errors import FMUError, StudyError, TsidError
from tsid_fmu.runner import Evaluation, Evaluator, PreparedExperiment, prepare_experiments
from tsid_fmu.study import Study

__all__ = ["ParallelEvaluator", "available_cores", "make_evaluator"]

Progress = Callable[[int, int], None]
_SHUTDOWN_GRACE = 2.0  # seconds a worker gets to close its FMU before it is killed
_PREFETCH = 2  # tasks in flight per local worker


def available_cores() -> int:
    """Return the number of CPU cores this process may run on (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def make_evaluator(
    study: Study,
    experiments: Sequence[int] | None = None,
    *,
    workers: int | None = None,
    timeout: float | None = None,
    scheduler: Any = None,
    recycle_after: int | None = None,
) -> Evaluator | ParallelEvaluator:
    """Return the evaluator for a study: serial in-process or parallel.

    Parameters
    ----------
    study : Study
        The study.
    experiments : sequence of int, optional
        Indices of the experiments to use (default: all).
    workers : int, optional
        Worker processes; default the number of available cores.
    timeout : float, optional
        Per-simulation time limit in seconds (needs worker processes).
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``"tcp://host:8786"``) or client.
    recycle_after : int, optional
        Replace each local worker after this many tasks.

    Returns
    -------
    Evaluator or ParallelEvaluator
        A serial :class:`~tsid_fmu.runner.Evaluator` when one worker is asked for (or
        only one core is available) and neither ``timeout``, ``scheduler`` nor
        ``recycle_after`` is given; else a :class:`ParallelEvaluator`.
    """
    n = available_cores() if workers is None else int(workers)
    if n == 1 and timeout is None and scheduler is None and recycle_after is None:
        return Evaluator(study, experiments)
    return ParallelEvaluator(
        study,
        experiments,
        workers=workers,
        timeout=timeout,
        scheduler=scheduler,
        recycle_after=recycle_after,
    )


# ---------------------------------------------------------------------------------------
# What a worker does (local process or Dask): one Evaluator, reused for every task
# ---------------------------------------------------------------------------------------


def _portable(
    study: Study, prepared: Sequence[PreparedExperiment], indices: Sequence[int]
) -> Study:
    """Return ``study`` with the used experiments' data already loaded (no file access)."""
    experiments = list(study.experiments)
    for i, p in zip(indices, prepared, strict=True):
        experiments[i] = dataclasses.replace(experiments[i], data=p.data)
    return dataclasses.replace(study, experiments=experiments)


class _Runner:
    """A worker's evaluator: runs one replicate of one parameter set per task."""

    def __init__(self, study: Study, indices: Sequence[int]) -> None:
        from tsid_fmu.fmu.compiled import warm_up

        self.evaluator = Evaluator(study, list(indices))
        warm_up()  # load the compiled loop now, not in the first (timed) task
        self.reps = [list(p.replicate_inputs) for p in self.evaluator.prepared]

    def replicate(self, params: Mapping[str, float], r: int) -> tuple[float, str | None, int, int]:
        """Return ``(cost, error, experiment index of the error, nfev)`` of replicate r.

        ``r = -1`` scores the measured inputs themselves (no added noise).
        """
        ev = self.evaluator
        for p, reps in zip(ev.prepared, self.reps, strict=True):
            p.replicate_inputs = [p.inputs if r < 0 else reps[min(r, len(reps) - 1)]]
        before = ev.nfev
        result = ev.evaluate([params])
        nfev = ev.nfev - before
        # the serial loop stops a row at its first failure, so nfev - 1 is where it failed
        return float(result.costs[0, 0]), result.errors[0], nfev - 1, nfev

    def clean(self, params: Mapping[str, float]) -> list[tuple[np.ndarray | None, str | None]]:
        """Noise-free simulation of every experiment."""
        for p, reps in zip(self.evaluator.prepared, self.reps, strict=True):
            p.replicate_inputs = reps
        return [(y, err) for _p, y, err in self.evaluator.simulate_clean(params)]

    def close(self) -> None:
        self.evaluator.close()


def _worker_main(conn: Connection, study: Study, indices: list[int]) -> None:
    """Entry point of a local worker process: build the runner, then serve tasks."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business
    try:
        runner = _Runner(study, indices)
    except BaseException as exc:
        conn.send(("init_error", _portable_error(exc)))
        return
    conn.send(("ready", os.getpid()))
    try:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                return
            kind = msg[0]
            if kind == "run":
                _, task, params, r = msg
                try:
                    reply = ("done", task, *runner.replicate(params, r))
                except Exception as exc:  # never lose the reason of a failed row
                    reply = ("done", task, math.inf, _reason(exc), 0, 1)
                conn.send(reply)
            elif kind == "clean":
                try:
                    conn.send(("clean", msg[1], runner.clean(msg[2])))
                except Exception as exc:
                    conn.send(("failed", msg[1], _reason(exc)))
            else:  # "stop"
                return
    finally:
        runner.close()


def _reason(exc: BaseException) -> str:
    """Text of an exception for a row's error (type named unless it is our own)."""
    return str(exc) if isinstance(exc, TsidError) else f"{type(exc).__name__}: {exc}"


def _portable_error(exc: BaseException) -> TsidError:
    """Turn an exception into a picklable TsidError of the same kind, message kept."""
    if isinstance(exc, TsidError):
        try:
            pickle.loads(pickle.dumps(exc))
            return exc
        except Exception:
            return (
                type(exc)(str(exc))
                if type(exc).__module__ == "tsid_fmu.errors"
                else FMUError(str(exc))
            )
    return FMUError(f"the worker could not start: {type(exc).__name__}: {exc}")


def _exit_reason(code: int | None) -> str:
    """Describe how a worker process ended."""
    if code is None:
        return "worker stopped responding"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = "unknown signal"
        return f"worker crashed (signal {-code} {name})"
    return f"worker exited with status {code}"


# ---------------------------------------------------------------------------------------
# Local worker pool
# ---------------------------------------------------------------------------------------


@contextlib.contextmanager
def _main_module_hidden() -> Iterator[None]:
    """Start a process without it re-importing the ``__main__`` script.

    ``spawn``/``forkserver`` children normally re-run the parent's main script, which
    starts the study again in a script without an ``if __name__ == "__main__":``
    guard. Workers need nothing from ``__main__`` (their target and arguments are
    tsid-fmu objects), so the main module is hidden while the process starts.
    """
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__tsid_worker_main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


class _Worker:
    """One worker process and the tasks sent to it (the first one is running)."""

    def __init__(self, ctx: Any, study: Study, indices: list[int], number: int) -> None:
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(
            target=_worker_main,
            args=(child, study, indices),
            name=f"tsid-worker-{number}",
            daemon=True,
        )
        with _main_module_hidden():
            self.process.start()
        child.close()
        self.ready = False
        self.inflight: deque[tuple] = deque()  # messages sent, oldest (running) first
        self.deadline = math.inf  # for the running task
        self.sent = 0

    def send(self, msg: tuple, limit: float | None) -> None:
        if not self.inflight:
            self.deadline = math.inf if limit is None else time.monotonic() + limit
        self.inflight.append(msg)
        self.sent += 1
        self.conn.send(msg)

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.conn.close()

    def stop(self) -> None:
        try:
            self.conn.send(("stop",))
        except (OSError, EOFError, BrokenPipeError):
            pass
        self.process.join(_SHUTDOWN_GRACE)
        self.kill()


class _LocalPool:
    """Worker processes that run tasks, survive crashes and enforce time limits."""

    def __init__(
        self,
        study: Study,
        indices: list[int],
        n_workers: int,
        timeout: float | None,
        recycle_after: int | None,
        start_method: str | None,
    ) -> None:
        if start_method is None:
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        self.ctx = mp.get_context(start_method)
        if start_method == "forkserver":
            self.ctx.set_forkserver_preload(["tsid_fmu._preload"])
        self.study, self.indices = study, indices
        self.timeout = timeout
        self.recycle_after = recycle_after
        self.sims_per_task = len(indices)
        self._count = 0
        self.workers: list[_Worker] = []
        for _ in range(n_workers):
            self._spawn()
        self._wait_ready(raise_errors=True)

    def _spawn(self) -> _Worker:
        self._count += 1
        w = _Worker(self.ctx, self.study, self.indices, self._count)
        self.workers.append(w)
        return w

    def _wait_ready(self, raise_errors: bool) -> None:
        """Block until every starting worker is ready; raise its error at start-up."""
        while True:
            starting = [w for w in self.workers if not w.ready]
            if not starting:
                return
            wait([w.conn for w in starting] + [w.process.sentinel for w in starting])
            for w in starting:
                self._handle_startup(w, raise_errors)

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
                f"{self.study.fmu.name}: a worker process failed to start "
                f"({_exit_reason(w.process.exitcode)})"
            )
        )
        if raise_errors:
            self.close()
            raise error
        warnings.warn(f"tsid_fmu.parallel: replacement worker failed: {error}", stacklevel=3)

    def _replace(self, w: _Worker) -> None:
        if w in self.workers:
            self.workers.remove(w)
        w.kill()
        self._spawn()

    def run(self, tasks: list[tuple], on_result: Callable[[Any, tuple], None]) -> None:
        """Run ``tasks`` (messages ``(kind, id, ...)``); call ``on_result(id, reply)``.

        Each worker has up to ``_PREFETCH`` tasks in flight, so it never waits for this
        process between tasks. A crash or time-out fails the running task with
        ``("failed", id, reason)``; the worker's queued tasks go to another worker.
        """
        pending = list(reversed(tasks))
        limit = None if self.timeout is None else self.timeout * self.sims_per_task
        quota = self.recycle_after
        while pending or any(w.inflight for w in self.workers):
            for w in list(self.workers):
                while (
                    w.ready
                    and pending
                    and len(w.inflight) < _PREFETCH
                    and (quota is None or w.sent < quota)
                ):
                    msg = pending.pop()
                    try:
                        w.send(msg, limit)
                    except (OSError, BrokenPipeError):  # died: the sentinel tells below
                        break
            if not self.workers:
                for msg in pending:
                    on_result(msg[1], ("failed", msg[1], "no worker process is left"))
                return
            busy = [w for w in self.workers if w.inflight or not w.ready]
            wait_for = min((w.deadline for w in busy), default=math.inf) - time.monotonic()
            ready = wait(
                [w.conn for w in busy] + [w.process.sentinel for w in busy],
                timeout=None if math.isinf(wait_for) else max(wait_for, 0.0),
            )
            for w in busy:
                if not w.ready:
                    if w.conn in ready or w.process.sentinel in ready:
                        self._handle_startup(w, raise_errors=False)
                    continue
                while w.inflight and w.conn.poll():
                    try:
                        reply = w.conn.recv()
                    except (EOFError, OSError):
                        break
                    msg = w.inflight.popleft()
                    w.deadline = math.inf if limit is None else time.monotonic() + limit
                    on_result(msg[1], reply)
                if not w.inflight and quota is not None and w.sent >= quota:
                    self.workers.remove(w)  # recycle: a fresh process for the next tasks
                    w.stop()
                    self._spawn()
                    continue
                if not w.inflight:
                    continue
                dead = w.process.sentinel in ready or not w.process.is_alive()
                if dead or time.monotonic() >= w.deadline:
                    if dead:
                        w.process.join(5)
                        reason = f"{_exit_reason(w.process.exitcode)}; the worker was replaced"
                    else:
                        reason = (
                            f"time limit of {self.timeout:g} s per simulation exceeded; "
                            "the worker was killed and replaced"
                        )
                    running = w.inflight.popleft()
                    pending.extend(w.inflight)  # queued behind the failed task: run elsewhere
                    w.inflight.clear()
                    on_result(running[1], ("failed", running[1], reason))
                    self._replace(w)

    def close(self) -> None:
        workers, self.workers = self.workers, []
        for w in workers:
            try:
                w.conn.send(("stop",))
            except (OSError, EOFError, BrokenPipeError):
                pass
        deadline = time.monotonic() + _SHUTDOWN_GRACE
        for w in workers:
            if w.ready:  # a worker still starting would only read "stop" once ready
                w.process.join(max(deadline - time.monotonic(), 0.0))
            w.kill()


# ---------------------------------------------------------------------------------------
# Dask
# ---------------------------------------------------------------------------------------

_DASK_IDLE: dict[str, list[Any]] = {}  # token -> runners not in use (this process)
_DASK_FOLDERS: dict[str, list[str]] = {}
_DASK_LOCK = threading.Lock()


class _IsolatedRunner:
    """A :class:`_Runner` in a child process of the Dask worker (crash and hang isolation).

    An FMU that crashes would otherwise kill the Dask worker, and Dask would retry the
    task on other workers until they are all gone; here only the child dies, the task
    returns a failed row, and the next task gets a new child.
    """

    def __init__(self, study: Study, indices: list[int], timeout: float | None) -> None:
        self.n_exp = len(indices)
        with _children_allowed():
            self.pool = _LocalPool(study, indices, 1, timeout, None, None)

    def _run(self, msg: tuple) -> tuple:
        box: list[tuple] = []
        with _children_allowed():
            self.pool.run([msg], lambda task, reply: box.append(reply))
        return box[0]

    def replicate(self, params: Mapping[str, float], r: int) -> tuple[float, str | None, int, int]:
        reply = self._run(("run", 0, dict(params), r))
        if reply[0] == "done":
            return reply[2], reply[3], reply[4], reply[5]
        return math.inf, f"replicate {r + 1}: {reply[2]}", self.n_exp, 1

    def clean(self, params: Mapping[str, float]) -> list[tuple[np.ndarray | None, str | None]]:
        reply = self._run(("clean", 0, dict(params)))
        if reply[0] == "clean":
            return reply[2]
        return [(None, reply[2])] * self.n_exp

    def close(self) -> None:
        self.pool.close()


@contextlib.contextmanager
def _children_allowed() -> Iterator[None]:
    """Let a daemonic process (a Dask worker) start worker processes of its own."""
    config = mp.current_process()._config  # type: ignore[attr-defined]
    daemon = config.get("daemon")
    config["daemon"] = False
    try:
        yield
    finally:
        if daemon is not None:
            config["daemon"] = daemon


def _dask_acquire(token: str, payload: tuple) -> _Runner | _IsolatedRunner:
    """Take an idle runner for ``token`` in this worker process, or build one."""
    with _DASK_LOCK:
        idle = _DASK_IDLE.setdefault(token, [])
        if idle:
            return idle.pop()
    study, indices, fmu_name, fmu_bytes, timeout, isolate = payload
    folder = tempfile.mkdtemp(prefix="tsid-dask-")
    path = Path(folder) / fmu_name
    path.write_bytes(fmu_bytes)
    with _DASK_LOCK:
        _DASK_FOLDERS.setdefault(token, []).append(folder)
    study = dataclasses.replace(study, fmu=path)
    if isolate:
        return _IsolatedRunner(study, indices, timeout)
    return _Runner(study, indices)


def _dask_release_runner(token: str, runner: Any) -> None:
    with _DASK_LOCK:
        _DASK_IDLE.setdefault(token, []).append(runner)


def _dask_warm(token: str, payload: Any) -> int:
    """Build one runner on this worker before the first batch (run by ``Client.run``)."""
    _dask_release_runner(token, _dask_acquire(token, payload))
    return os.getpid()


def _dask_one(runner: Any, kind: str, params: Mapping[str, float], r: int) -> Any:
    if kind == "check":
        return None
    if kind == "clean":
        return runner.clean(params)
    try:
        return runner.replicate(params, r)
    except Exception as exc:
        return math.inf, _reason(exc), 0, 1


def _dask_batch(token: str, payload: Any, items: list[tuple[str, dict, int]]) -> list[Any]:
    """Run several tasks in one Dask task: one scheduler round trip for the chunk.

    Each item's result is returned in order; an item that raises returns
    ``("error", reason)`` so one bad row does not fail the chunk.
    """
    runner = _dask_acquire(token, payload)
    out: list[Any] = []
    try:
        for kind, params, r in items:
            try:
                out.append(("ok", _dask_one(runner, kind, params, r)))
            except Exception as exc:
                out.append(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        _dask_release_runner(token, runner)
    return out


def _dask_release(token: str) -> int:
    """Close this worker's runners of ``token`` and delete their FMU copies."""
    import shutil

    with _DASK_LOCK:
        runners = _DASK_IDLE.pop(token, [])
        folders = _DASK_FOLDERS.pop(token, [])
    for runner in runners:
        runner.close()
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return len(runners)


CHUNKS_PER_SLOT = 2


class _DaskPool:
    """Send tasks to a ``dask.distributed`` cluster."""

    def __init__(
        self,
        study: Study,
        indices: list[int],
        scheduler: Any,
        timeout: float | None,
        isolate: bool = True,
    ) -> None:
        try:
            from distributed import Client
        except ImportError as exc:
            raise StudyError(
                "running on a Dask scheduler needs dask.distributed: pip install tsid-fmu[dask]"
            ) from exc
        if isinstance(scheduler, str):
            try:
                self.client = Client(scheduler, timeout="20s")
            except OSError as exc:
                raise StudyError(
                    f"cannot connect to the Dask scheduler {scheduler}: {exc}"
                ) from exc
            self._own_client = True
        else:
            self.client = scheduler
            self._own_client = False
        try:
            fmu_bytes = Path(study.fmu).read_bytes()
        except OSError as exc:
            raise FMUError(f"cannot read the FMU {study.fmu}: {exc}") from exc
        blob = pickle.dumps((study, indices))
        self.token = hashlib.sha256(blob + fmu_bytes).hexdigest()[:16] + f"-{os.getpid()}"
        payload = (study, indices, Path(study.fmu).name, fmu_bytes, timeout, isolate)
        self.payload = self.client.scatter(payload, broadcast=True, hash=False)
        try:  # one runner per worker now: start-up is not paid inside the first batch
            self.client.run(_dask_warm, self.token, payload)
        except TsidError:
            self.close()
            raise
        except Exception:
            pass  # a worker that cannot build it reports the reason on its first task
        self.timeout = timeout
        self.sims_per_task = len(indices)
        self.fmu_name = Path(study.fmu).name
        # build the runner on one worker now, so a bad FMU fails here as in serial
        check = self.client.submit(
            _dask_batch, self.token, self.payload, [("check", {}, 0)], pure=False
        )
        try:
            check.result()
        except TsidError:
            self.close()
            raise
        except Exception as exc:
            self.close()
            raise FMUError(f"{self.fmu_name}: the Dask worker could not start: {exc}") from exc

    def run(self, tasks: list[tuple], on_result: Callable[[Any, tuple], None]) -> None:
        from distributed import as_completed

        # Tasks go in chunks, CHUNKS_PER_SLOT per worker thread: every Dask task costs
        # a worker -> scheduler -> worker round trip (the scheduler queues what the
        # workers do not hold), which on a small machine competes for the cores with the
        # simulations themselves (48 single tasks on 2 workers: 0.75 N; chunked: see
        # benchmarks/bench_dask.py). The chunks are balanced, so the tail stays short.
        # Each chunk is placed on a worker in turn (by its threads), so every worker gets
        # its share at once; left to itself the scheduler sometimes gave one of two
        # workers three chunks of four. A chunk can still move when its worker is gone.
        info = self.client.scheduler_info().get("workers", {})
        places = [a for a, w in sorted(info.items()) for _ in range(int(w.get("nthreads", 1)))]
        slots = max(1, len(places))
        n_chunks = max(1, min(len(tasks), CHUNKS_PER_SLOT * slots))
        chunks = [tasks[i::n_chunks] for i in range(n_chunks)]
        futures = {}
        for i, chunk in enumerate(chunks):
            items = [(msg[0], msg[2], msg[3] if msg[0] == "run" else 0) for msg in chunk]
            place = {"workers": [places[i % len(places)]]} if places else {}
            fut = self.client.submit(
                _dask_batch,
                self.token,
                self.payload,
                items,
                pure=False,
                retries=0,
                allow_other_workers=True,
                **place,
            )
            futures[fut] = chunk
        budget = None
        if self.timeout is not None:
            # the limit is enforced on the Dask workers (_IsolatedRunner); this is only a
            # backstop for a worker that stops answering altogether
            rounds = math.ceil(len(tasks) / slots)
            budget = 2 * self.timeout * self.sims_per_task * rounds + 30.0
        finished = set()
        try:
            for fut in as_completed(list(futures), timeout=budget):
                finished.add(fut)
                chunk = futures[fut]
                try:
                    values = fut.result()
                except Exception as exc:  # KilledWorker when the FMU crashed the worker
                    reason = f"Dask task failed: {type(exc).__name__}: {exc}"
                    for msg in chunk:
                        on_result(msg[1], ("failed", msg[1], reason))
                    continue
                for msg, (status, value) in zip(chunk, values, strict=True):
                    kind, task = msg[0], msg[1]
                    if status != "ok":
                        on_result(task, ("failed", task, f"Dask task failed: {value}"))
                    elif kind == "clean":
                        on_result(task, ("clean", task, value))
                    else:
                        on_result(task, ("done", task, *value))
        except TimeoutError:
            pass
        late = [fut for fut in futures if fut not in finished]
        for fut in late:
            for msg in futures[fut]:
                on_result(msg[1], ("failed", msg[1], "time limit exceeded on the Dask cluster"))
        if late:
            self.client.cancel(late)

    def close(self) -> None:
        try:
            self.client.run(_dask_release, self.token)
        except Exception:
            pass
        if self._own_client:
            self.client.close()


# ---------------------------------------------------------------------------------------
# The evaluator
# ---------------------------------------------------------------------------------------


class ParallelEvaluator:
    """Score parameter sets on worker processes or a Dask cluster (context manager).

    Parameters
    ----------
    study : Study
        The study.
    experiments : sequence of int, optional
        Indices of the experiments to use (default: all).
    workers : int, optional
        Local worker processes; default the number of available cores. Ignored with
        ``scheduler``.
    timeout : float, optional
        Time limit per simulation, seconds: a task past it is stopped (its worker
        process killed and replaced) and its row fails.
    scheduler : str or distributed.Client, optional
        Run on this Dask cluster instead of local processes.
    recycle_after : int, optional
        Replace a local worker after this many tasks.
    start_method : {"forkserver", "spawn"}, optional
        How local workers start; default ``forkserver`` where available (a forked copy
        of a small server process that has imported tsid-fmu, never of this process).

    Attributes
    ----------
    prepared : list of PreparedExperiment
        The experiments' data and replicate inputs, as the workers use them.
    nfev : int
        Simulations run so far.

    Raises
    ------
    FMUError, StudyError
        As :class:`~tsid_fmu.runner.Evaluator` does (the workers' start-up errors are
        raised here), or when Dask is missing or its scheduler cannot be reached.
    """

    def __init__(
        self,
        study: Study,
        experiments: Sequence[int] | None = None,
        *,
        workers: int | None = None,
        timeout: float | None = None,
        scheduler: Any = None,
        recycle_after: int | None = None,
        start_method: str | None = None,
    ) -> None:
        if workers is not None and int(workers) < 1:
            raise StudyError(f"workers must be at least 1, got {workers}")
        if timeout is not None and not (timeout > 0):
            raise StudyError(f"timeout must be a positive number of seconds, got {timeout}")
        if recycle_after is not None and int(recycle_after) < 1:
            raise StudyError(f"recycle_after must be at least 1, got {recycle_after}")
        self.study = study
        indices = list(range(len(study.experiments))) if experiments is None else list(experiments)
        self.prepared = prepare_experiments(study, indices)
        self.nfev = 0
        self.workers = available_cores() if workers is None else int(workers)
        self.timeout = timeout
        portable = _portable(study, self.prepared, indices)
        self._pool: _LocalPool | _DaskPool
        if scheduler is not None:
            self._pool = _DaskPool(portable, indices, scheduler, timeout)
        else:
            self._pool = _LocalPool(
                portable, indices, self.workers, timeout, recycle_after, start_method
            )

    @property
    def n_replicates(self) -> int:
        """Replicates per parameter set (1 when the study adds no noise)."""
        return max(len(p.replicate_inputs) for p in self.prepared)

    def evaluate(
        self,
        parameter_sets: Sequence[Mapping[str, float]],
        progress: Progress | None = None,
        *,
        clean: bool = False,
    ) -> Evaluation:
        """Simulate and score each parameter set, in parallel.

        Parameters
        ----------
        parameter_sets : sequence of mapping
            Parameter values by name, one mapping per set.
        progress : callable, optional
            Called as ``progress(done, total)`` each time a set is finished.
        clean : bool
            Score the measured inputs themselves (one column of costs, no added noise)
            instead of the noise replicates.

        Returns
        -------
        Evaluation
            Costs per set and replicate (bit-identical to the serial evaluator's), and
            failure reasons; a crashed or timed-out task gives ``inf`` and its reason.
        """
        n_sets, n_rep = len(parameter_sets), 1 if clean else self.n_replicates
        costs = np.zeros((n_sets, n_rep))
        failures: list[list[tuple[int, int, str]]] = [[] for _ in range(n_sets)]
        left = [n_rep] * n_sets
        state = {"nfev": 0, "finished": 0}
        n_exp = len(self.prepared)

        def on_result(task: tuple[int, int], reply: tuple) -> None:
            i, r = task
            if reply[0] == "done":
                _, _, cost, error, at, nfev = reply
                costs[i, r] = cost
                state["nfev"] += nfev
                if error is not None:
                    failures[i].append((at, r, error))
            else:  # crash or time limit: which experiment is unknown, count one run
                costs[i, r] = math.inf
                state["nfev"] += 1
                failures[i].append((n_exp, r, f"replicate {r + 1}: {reply[2]}"))
            left[i] -= 1
            if left[i] == 0:
                state["finished"] += 1
                if progress is not None:
                    progress(state["finished"], n_sets)

        tasks = [
            ("run", (i, r), dict(params), -1 if clean else r)
            for i, params in enumerate(parameter_sets)
            for r in range(n_rep)
        ]
        if tasks:
            self._pool.run(tasks, on_result)
        errors: list[str | None] = [None] * n_sets
        for i, fails in enumerate(failures):
            if fails:
                errors[i] = min(fails, key=lambda f: (f[0], f[1]))[2]
                costs[i, :] = math.inf
        self.nfev += state["nfev"]
        return Evaluation(costs=costs, errors=errors, nfev=state["nfev"])

    def simulate_clean(
        self, params: Mapping[str, float]
    ) -> list[tuple[PreparedExperiment, np.ndarray | None, str | None]]:
        """Simulate each experiment with its measured (noise-free) input, on a worker.

        Returns
        -------
        list of tuple
            ``(prepared experiment, simulated outputs or None, error or None)``.
        """
        return self.simulate_clean_many([params])[0]

    def simulate_clean_many(
        self, parameter_sets: Sequence[Mapping[str, float]]
    ) -> list[list[tuple[PreparedExperiment, np.ndarray | None, str | None]]]:
        """:meth:`simulate_clean` for several parameter sets, run in parallel."""
        replies: dict[int, tuple] = {}

        def on_result(task: Any, reply: tuple) -> None:
            replies[task] = reply

        self._pool.run([("clean", i, dict(p)) for i, p in enumerate(parameter_sets)], on_result)
        self.nfev += len(self.prepared) * len(parameter_sets)
        out = []
        for i in range(len(parameter_sets)):
            reply = replies.get(i)
            if reply is None or reply[0] != "clean":
                reason = reply[2] if reply is not None else "no result"
                out.append([(p, None, f"{p.experiment.name}: {reason}") for p in self.prepared])
            else:
                out.append(
                    [(p, y, err) for p, (y, err) in zip(self.prepared, reply[2], strict=True)]
                )
        return out

    def close(self) -> None:
        """Stop the workers (they free their FMU instances and extracted folders)."""
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.close()
            del self._pool

    def __enter__(self) -> ParallelEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    def __repr__(self) -> str:
        where = (
            "dask"
            if isinstance(getattr(self, "_pool", None), _DaskPool)
            else f"{self.workers} workers"
        )
        return f"ParallelEvaluator({self.study.name!r}, {where}, nfev={self.nfev})"
