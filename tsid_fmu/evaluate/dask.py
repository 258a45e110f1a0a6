"""Evaluate parameter sets on a Dask cluster.

:class:`DaskEvaluator` sends the parameter sets of a batch to a ``dask.distributed``
cluster. The FMU file travels with the spec (which holds the measured data already), so
the workers need only ``tsid-fmu`` installed, not the study's files. On each Dask worker
the FMU runs in a child process of the worker (a one-worker
:class:`~tsid_fmu.evaluate.workers.LocalPool`), so crashes and the time limit are
handled there exactly as locally, and a crashing FMU never takes a Dask worker down.
Results, errors and ``nfev`` are those of the serial evaluator.

Dask is optional: ``pip install tsid-fmu[dask]``; it is imported only here, when an
evaluator is made.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import pickle
import shutil
import tempfile
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tsid_fmu.errors import FMUError, StudyError, TsidError
from tsid_fmu.evaluate.memo import RESIDUAL_CACHE, MemoEvaluator
from tsid_fmu.evaluate.runner import Job, OnResult, SetResult, SimResult, failed_result
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.evaluate.timelimit import TimeLimit
from tsid_fmu.evaluate.workers import LocalPool, children_allowed

__all__ = ["CHUNKS_PER_SLOT", "DaskEvaluator"]

CHUNKS_PER_SLOT = 2
"""Chunks of parameter sets per Dask worker thread and batch."""

# -- on the Dask workers -----------------------------------------------------------------

_IDLE: dict[str, list[Any]] = {}  # token -> runners not in use (in this worker process)
_FOLDERS: dict[str, list[str]] = {}
_LOCK = threading.Lock()


class _IsolatedRunner:
    """A one-process :class:`LocalPool` in a child of the Dask worker (crash isolation).

    An FMU that crashes would otherwise kill the Dask worker, and Dask would retry the
    task on other workers until they are all gone; here only the child dies, the set
    fails, and the next job gets a new child.
    """

    def __init__(self, spec: EvaluationSpec, timeout: float | None) -> None:
        with children_allowed():
            self.pool = LocalPool(spec, 1, TimeLimit(timeout))

    def run(self, job: Job) -> SetResult | SimResult:
        box: list[Any] = []
        with children_allowed():
            self.pool.run([job], lambda index, result: box.append(result))
        return box[0]

    def end_batch(self) -> None:
        self.pool.limit.end_batch()

    def close(self) -> None:
        self.pool.close()


def _acquire(token: str, payload: tuple) -> _IsolatedRunner:
    """Take an idle runner for ``token`` in this worker process, or build one."""
    with _LOCK:
        idle = _IDLE.setdefault(token, [])
        if idle:
            return idle.pop()
    spec, fmu_name, fmu_bytes, timeout = payload
    folder = tempfile.mkdtemp(prefix="tsid-dask-")
    path = Path(folder) / fmu_name
    path.write_bytes(fmu_bytes)
    with _LOCK:
        _FOLDERS.setdefault(token, []).append(folder)
    return _IsolatedRunner(dataclasses.replace(spec, fmu=path), timeout)


def _release_runner(token: str, runner: _IsolatedRunner) -> None:
    with _LOCK:
        _IDLE.setdefault(token, []).append(runner)


def _warm(token: str, payload: Any) -> int:
    """Build one runner on this worker before the first batch (run by ``Client.run``)."""
    _release_runner(token, _acquire(token, payload))
    return os.getpid()


def _batch(token: str, payload: Any, jobs: list[Job]) -> list[tuple[str, Any]]:
    """Run several jobs in one Dask task: one scheduler round trip for the chunk.

    Returns ``("ok", result)`` per job, or ``("error", reason)`` for a job that raised,
    so one bad set does not fail the chunk.
    """
    runner = _acquire(token, payload)
    out: list[tuple[str, Any]] = []
    try:
        for job in jobs:
            try:
                out.append(("ok", runner.run(job)))
            except Exception as exc:
                out.append(("error", f"{type(exc).__name__}: {exc}"))
        runner.end_batch()
    finally:
        _release_runner(token, runner)
    return out


def _release(token: str) -> int:
    """Close this worker's runners of ``token`` and delete their FMU copies."""
    with _LOCK:
        runners = _IDLE.pop(token, [])
        folders = _FOLDERS.pop(token, [])
    for runner in runners:
        runner.close()
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return len(runners)


# -- in the calling process --------------------------------------------------------------


def _client(scheduler: Any) -> tuple[Any, bool]:
    """Return ``(client, owned)`` for a scheduler address or an existing client."""
    try:
        from distributed import Client
    except ImportError as exc:
        raise StudyError(
            "running on a Dask scheduler needs dask.distributed: pip install tsid-fmu[dask]"
        ) from exc
    if not isinstance(scheduler, str):
        return scheduler, False
    try:
        return Client(scheduler, timeout="20s"), True
    except OSError as exc:
        raise StudyError(f"cannot connect to the Dask scheduler {scheduler}: {exc}") from exc


class DaskEvaluator(MemoEvaluator):
    """Score parameter sets on a ``dask.distributed`` cluster (context manager).

    Parameters
    ----------
    spec : EvaluationSpec
        What to simulate and how to score it.
    scheduler : str or distributed.Client
        The scheduler's address (``"tcp://host:8786"``) or a client.
    timeout : float, optional
        Time limit per simulation, applied on the Dask workers: ``None`` automatic, ``0``
        none, else seconds (see :mod:`tsid_fmu.evaluate.timelimit`).
    residual_cache : int, optional
        Parameter sets whose residuals are kept (default 256).

    Raises
    ------
    StudyError
        Dask is not installed or the scheduler cannot be reached.
    FMUError
        The FMU cannot be read, or cannot be opened on a worker (raised as serially).
    """

    def __init__(
        self,
        spec: EvaluationSpec,
        scheduler: Any,
        *,
        timeout: float | None = None,
        residual_cache: int = RESIDUAL_CACHE,
    ) -> None:
        super().__init__(spec, residual_cache=residual_cache)
        self.limit = TimeLimit(timeout)  # checks the value; applied on the workers
        self.client, self._own_client = _client(scheduler)
        self._open = True
        self.token = ""
        if spec.variants is not None:  # the workers get one FMU file's bytes
            self.close()
            raise StudyError(
                f"a choice among FMU files ({spec.variants.name}) does not run on a Dask "
                "scheduler yet; run it with local workers (--workers N)"
            )
        try:
            fmu_bytes = Path(spec.fmu).read_bytes()
        except OSError as exc:
            self.close()
            raise FMUError(f"cannot read the FMU {spec.fmu}: {exc}") from exc
        blob = pickle.dumps(spec)
        self.token = hashlib.sha256(blob + fmu_bytes).hexdigest()[:16] + f"-{os.getpid()}"
        payload = (spec, Path(spec.fmu).name, fmu_bytes, timeout)
        self.payload = self.client.scatter(payload, broadcast=True, hash=False)
        try:  # one runner per worker now: start-up is not paid inside the first batch
            self.client.run(_warm, self.token, payload)
        except TsidError:
            self.close()
            raise
        except Exception:
            pass  # a worker that cannot build it reports the reason on its first job
        self._check()

    def _check(self) -> None:
        """Build a runner on one worker now, so that a bad FMU fails here as serially."""
        check = self.client.submit(_batch, self.token, self.payload, [], pure=False)
        try:
            check.result()
        except TsidError:
            self.close()
            raise
        except Exception as exc:
            self.close()
            raise FMUError(f"{self.spec.fmu.name}: the Dask worker could not start: {exc}") from exc

    def _places(self) -> list[str]:
        info = self.client.scheduler_info().get("workers", {})
        return [a for a, w in sorted(info.items()) for _ in range(int(w.get("nthreads", 1)))]

    def _run_jobs(self, jobs: list[Job], on_result: OnResult) -> None:
        # Jobs go in chunks, CHUNKS_PER_SLOT per worker thread: every Dask task costs a
        # worker -> scheduler -> worker round trip, which on a small machine competes for
        # the cores with the simulations (benchmarks/bench_dask.py). Each chunk is placed
        # on a worker in turn, so every worker gets its share at once; a chunk can still
        # move when its worker is gone.
        places = self._places()
        slots = max(1, len(places))
        n_chunks = max(1, min(len(jobs), CHUNKS_PER_SLOT * slots))
        chunks = [list(range(len(jobs)))[i::n_chunks] for i in range(n_chunks)]
        futures = {}
        for c, chunk in enumerate(chunks):
            place = {"workers": [places[c % len(places)]]} if places else {}
            fut = self.client.submit(
                _batch,
                self.token,
                self.payload,
                [jobs[i] for i in chunk],
                pure=False,
                retries=0,
                allow_other_workers=True,
                **place,
            )
            futures[fut] = chunk
        self._collect(futures, jobs, on_result, self._budget(len(jobs), slots))

    def _budget(self, n_jobs: int, slots: int) -> float | None:
        """Backstop for a worker that stops answering (the limit itself is on the workers)."""
        limit = None if self.limit.auto else self.limit.seconds()
        if limit is None:
            return None
        rounds = math.ceil(n_jobs / slots)
        return 2 * limit * self.spec.n_simulations * rounds + 30.0

    def _collect(
        self,
        futures: Mapping[Any, list[int]],
        jobs: list[Job],
        on_result: OnResult,
        budget: float | None,
    ) -> None:
        from distributed import as_completed

        finished = set()
        try:
            for fut in as_completed(list(futures), timeout=budget):
                finished.add(fut)
                chunk = futures[fut]
                try:
                    values = fut.result()
                except Exception as exc:  # KilledWorker, lost worker
                    values = [("error", f"{type(exc).__name__}: {exc}")] * len(chunk)
                for i, (status, value) in zip(chunk, values, strict=True):
                    if status != "ok":
                        value = failed_result(self.spec, jobs[i][0], f"Dask task failed: {value}")
                    on_result(i, value)
        except TimeoutError:
            pass
        except BaseException:  # interrupted: nothing of this call may run on
            self.client.cancel([fut for fut in futures if fut not in finished])
            raise
        late = [fut for fut in futures if fut not in finished]
        for fut in late:
            for i in futures[fut]:
                reason = "time limit exceeded on the Dask cluster"
                on_result(i, failed_result(self.spec, jobs[i][0], reason))
        if late:
            self.client.cancel(late)

    def close(self) -> None:
        """Close the runners on the workers (and the client if this evaluator made it)."""
        if not getattr(self, "_open", False):
            return
        self._open = False
        try:
            self.client.run(_release, self.token)
        except Exception:
            pass
        if self._own_client:
            self.client.close()

    def __repr__(self) -> str:
        return f"DaskEvaluator({self.spec.fmu.name!r}, nfev={self.nfev})"
