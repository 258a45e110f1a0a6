"""The audit trail of a study on disk: one folder per iteration, written as it ends.

Layout of the output folder::

    fingerprint.json           the normalised study, FMU and data hashes (who owns it)
    .tsid.lock                 locked (fcntl.flock) while a study writes the folder
    study.toml                 the study file, as run
    iteration_01/ ...          the Taguchi stage of a one-group study:
        levels.csv             levels of each factor
        runs.csv               array rows: levels, values, cost per replicate, S/N, errors
        response.csv           mean S/N per level, delta, rank (the response table)
        response_means.csv     mean cost per level, delta, rank
        anova.csv              ANOVA of the S/N with percent contribution
        decision.json          re-leveling case and reason per factor
        next_levels.toml       proposed levels of the next iteration (a person may edit)
        main_effects.svg, fit.svg  drawn at the end of the study (report/render.py)
        record.json            written last: marks the iteration complete; lists the
                               hashes of the files above and carries its own digest
    stage.json                 the finished Taguchi stage of a one-group study
    contribution/stage.json    the contribution analyses of a phased study
    phase_01/ ...              each phase: iteration_NN/ and stage.json
    refinement/stage.json      the refinement stage
    result.json, parameters.csv, parameters.ssv, model.ssp
    jacobian.npy               the residual Jacobian at the answer (its hash in result.json)
    report.html, report.md, fit.png, convergence.png, parameters.png

Every file is written to a temporary name and renamed into place, so an interrupted
study leaves either the old file or the new one, never half of one. ``--resume`` reads
the complete iterations and finished stages back, checks their digests and file hashes
(:mod:`tsid_fmu.trail.integrity`) and continues; a folder of another study, or one
holding files tsid-fmu did not write, is refused (:mod:`tsid_fmu.trail.owner`).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable
from pathlib import Path

from tsid_fmu.errors import StudyError
from tsid_fmu.fmu import native
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.study.definition import Study
from tsid_fmu.trail.files import atomic_write, write_json
from tsid_fmu.trail.integrity import file_hashes, seal, unexpected_files
from tsid_fmu.trail.levels import read_next_levels, write_next_levels
from tsid_fmu.trail.owner import FolderLock, check_owner, fingerprint, write_fingerprint
from tsid_fmu.trail.reader import read_record, read_stage

__all__ = ["FMU_OUTPUT", "NullStore", "Trail"]

#: the file in a study folder that records what the FMU printed, run by run
FMU_OUTPUT = "fmu_output.log"


class NullStore:
    """A store that keeps nothing (a study run without an output folder)."""

    @property
    def notes(self) -> list[str]:
        """Return no warnings."""
        return []

    def iterations(self, key: str) -> list[IterationRecord]:
        """Return no iterations."""
        return []

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        """Return no edited levels."""
        return None

    def stage(self, key: str) -> StageResult | None:
        """Return no finished stage."""
        return None

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        """Keep nothing."""

    def write_stage(self, key: str, result: StageResult) -> None:
        """Keep nothing."""

    def close(self) -> None:
        """Nothing to release."""


class Trail:
    """Reads and writes the audit trail of one study, holding the folder's lock.

    Call :meth:`close` (or use it as a context manager) to release the lock.

    Parameters
    ----------
    out : path
        Output folder.
    study : Study
        The study whose trail this is.
    resume : bool
        Continue the study in ``out``; without it a folder holding a study is refused.
        A folder holding another study, or files tsid-fmu did not write, is refused
        either way, and left as it was.
    on_iteration : callable, optional
        Called as ``on_iteration(folder, record, space)`` after an iteration's tables
        are written and before its ``record.json`` (the report draws its plots there).
    """

    def __init__(
        self,
        out: str | Path,
        study: Study,
        resume: bool = False,
        on_iteration: Callable[[Path, IterationRecord, Space], None] | None = None,
    ) -> None:
        self.out = Path(out)
        self.study = study
        self.on_iteration = on_iteration
        self.notes: list[str] = []  # warnings about the folder, for the result
        items = fingerprint(study)
        check_owner(self.out, items, resume, locked=False)
        self.out.mkdir(parents=True, exist_ok=True)
        self._lock = FolderLock(self.out)
        self._lock.acquire()
        try:
            source = Path(study.source) if study.source is not None else None
            if check_owner(self.out, items, resume, locked=True):
                write_fingerprint(self.out, items)
                if source is not None and source.is_file():
                    atomic_write(self.out / "study.toml", source.read_bytes())
            elif source is not None and source.is_file():
                self._compare_copy(source)
        except BaseException:
            self._lock.release()
            raise
        # what the FMU prints natively, run by run, while this trail is open
        self._recording = contextlib.ExitStack()
        self._recording.enter_context(native.recording(self.out / FMU_OUTPUT))

    def _compare_copy(self, source: Path) -> None:
        """Note a copy ``study.toml`` that differs from the study file being resumed."""
        copy = self.out / "study.toml"
        if copy.is_file() and copy.read_bytes() != source.read_bytes():
            self.notes.append(
                f"{copy} differs from {source}, the study file being run (edited by hand?); "
                "the run follows the study file and leaves the copy as it is"
            )

    def close(self) -> None:
        """Stop recording the FMU's output; release the folder's lock."""
        try:
            self._recording.close()
        finally:
            self._lock.release()

    def __enter__(self) -> Trail:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stage_dir(self, key: str) -> Path:
        """Folder of a stage (``""`` is the output folder itself)."""
        return self.out / key if key else self.out

    def iteration_dir(self, key: str, index: int) -> Path:
        """Folder of iteration ``index`` of a stage."""
        return self.stage_dir(key) / f"iteration_{index:02d}"

    def iterations(self, key: str) -> list[IterationRecord]:
        """Return a stage's complete iterations; an interrupted one is removed (redone)."""
        records: list[IterationRecord] = []
        while (path := self.iteration_dir(key, len(records) + 1) / "record.json").exists():
            records.append(read_record(path, self._note_extra))
        if records and records[-1].parameters != self._parameters(records[-1]):
            raise StudyError(
                f"{self.stage_dir(key)}: the trail identifies {records[-1].parameters} but the "
                "study now has other parameters; use a new --out folder"
            )
        stale = self.iteration_dir(key, len(records) + 1)
        if stale.exists():
            shutil.rmtree(stale)
        return records

    def _note_extra(self, folder: Path, hashes: object) -> None:
        """Note files in an iteration's folder that tsid-fmu did not write (ignored)."""
        extra = unexpected_files(folder, hashes)
        note = (
            f"{folder}: {', '.join(map(repr, extra))} not written by tsid-fmu; ignored (an "
            "iteration is read from the files its record.json lists)"
        )
        if extra and note not in self.notes:
            self.notes.append(note)

    def _parameters(self, record: IterationRecord) -> list[str]:
        names = set(self.study.parameter_names) | set(self.study.choice_names)
        return record.parameters if set(record.parameters) <= names else sorted(names)

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        """Levels a person wrote into the last ``next_levels.toml``, if they differ."""
        path = self.iteration_dir(key, record.index) / "next_levels.toml"
        if not path.exists():
            return None
        frame = read_next_levels(path, space)
        proposed = record.next_rerun.frame if record.next_rerun else record.next_frame
        same = frame.to_dict()["factors"] == proposed.to_dict()["factors"] and (
            frame.axis_aligned
            or (list(frame.centre) == list(proposed.centre) and frame.anchor == proposed.anchor)
        )  # rotated: the [centre] a person writes is the anchor (an edit of it was ignored)
        return None if same else frame

    def stage(self, key: str) -> StageResult | None:
        """Return a finished stage written by :meth:`write_stage`, or None."""
        return read_stage(self.stage_dir(key), records=False)

    def write_stage(self, key: str, result: StageResult) -> None:
        """Mark a stage finished: its summary in ``stage.json``.

        The stage's folder (relative to the output folder) is kept in its
        ``extra["folder"]``, so that ``result.json`` names where each stage lies.
        """
        result.extra["folder"] = key
        write_json(self.stage_dir(key) / "stage.json", seal(result.to_dict()))

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        """Write every file of a finished iteration; ``record.json`` last."""
        d = self.iteration_dir(key, record.index)
        d.mkdir(parents=True, exist_ok=True)
        n = max(len(v) for v in record.levels.values())
        lines = ["factor," + ",".join(f"level {i + 1}" for i in range(n))]
        lines += [
            f + "," + ",".join(repr(float(v)) for v in record.levels[f]) for f in record.names
        ]
        atomic_write(d / "levels.csv", "\n".join(lines) + "\n")
        atomic_write(d / "runs.csv", record.runs_frame().to_csv(index=False))
        atomic_write(d / "response.csv", record.response.to_pandas().to_csv())
        atomic_write(d / "response_means.csv", record.response_means.to_pandas().to_csv())
        atomic_write(d / "anova.csv", record.anova.to_pandas().to_csv())
        write_json(d / "decision.json", record.decision.to_dict())
        nxt = record.next_rerun
        frame = nxt.frame if nxt else record.next_frame
        note = nxt.note if nxt else record.decision.message
        atomic_write(d / "next_levels.toml", write_next_levels(d, record, space, frame, note))
        if self.on_iteration is not None:
            self.on_iteration(d, record, space)
        write_json(d / "record.json", seal({**record.to_dict(), "files": file_hashes(d)}))

    def write_text(self, name: str, text: str) -> Path:
        """Write a text file into the output folder."""
        atomic_write(self.out / name, text)
        return self.out / name
