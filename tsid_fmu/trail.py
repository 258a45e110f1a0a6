"""The audit trail of a study on disk: one folder per iteration, written as it ends.

Layout of the output folder::

    study.toml                 copy of the study file
    iteration_01/
        levels.csv             levels of each parameter
        runs.csv               array rows: levels, values, cost per replicate, S/N, errors
        response.csv           mean S/N per level, delta, rank (the response table)
        anova.csv              ANOVA of the S/N with percent contribution
        decision.json          re-leveling case and reason per parameter
        next_levels.toml       proposed levels of the next iteration (a person may edit)
        main_effects.png       S/N main-effects plot (the papers' Figs. 7-9)
        fit.png                measured vs simulated output at the best set so far
        record.json            written last: marks the iteration complete
    result.json, parameters.csv, parameters.ssv, report.md, convergence.png, fit_*.png

Every file is written to a temporary name and renamed into place, so an interrupted
study leaves either the old file or the new one, never half of one. ``--resume`` reads
the complete iterations back and continues with the levels in the last
``next_levels.toml``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tsid_fmu.errors import StudyError

if TYPE_CHECKING:
    from tsid_fmu.engine import IdentificationResult, IterationRecord
    from tsid_fmu.runner import Evaluator
    from tsid_fmu.study import Study

__all__ = ["Trail", "atomic_write"]


def atomic_write(path: Path, write: Callable[[Path], None] | str | bytes) -> None:
    """Write a file atomically: to a temporary file in the same folder, then rename.

    Parameters
    ----------
    path : Path
        Destination.
    write : str, bytes or callable
        Content, or a function that writes the file at the path it is given.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        if isinstance(write, str):
            tmp_path.write_text(write, encoding="utf-8")
        elif isinstance(write, bytes):
            tmp_path.write_bytes(write)
        else:
            write(tmp_path)
        with open(tmp_path, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _fmt_list(values: list[float]) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


class Trail:
    """Reads and writes the audit trail of one study.

    Parameters
    ----------
    out : path
        Output folder.
    study : Study
        The study whose trail this is.
    """

    def __init__(self, out: str | Path, study: Study) -> None:
        self.out = Path(out)
        self.study = study

    def iteration_dir(self, index: int) -> Path:
        """Folder of iteration ``index``."""
        return self.out / f"iteration_{index:02d}"

    def open(self, resume: bool) -> list[IterationRecord]:
        """Prepare the folder; on resume return the complete iterations found in it."""
        from tsid_fmu.engine import IterationRecord

        existing = sorted(self.out.glob("iteration_*/record.json")) if self.out.is_dir() else []
        if existing and not resume:
            raise StudyError(
                f"{self.out} already holds a study ({len(existing)} iterations); continue it "
                "with --resume, or choose another --out folder"
            )
        if resume and not self.out.is_dir():
            raise StudyError(f"{self.out}: nothing to resume (no such folder)")
        self.out.mkdir(parents=True, exist_ok=True)
        if self.study.source is not None and not (self.out / "study.toml").exists():
            atomic_write(self.out / "study.toml", Path(self.study.source).read_bytes())
        records = []
        for i in range(1, len(existing) + 1):
            path = self.iteration_dir(i) / "record.json"
            if not path.exists():
                break
            try:
                records.append(IterationRecord.from_dict(json.loads(path.read_text())))
            except (ValueError, KeyError, TypeError) as exc:
                raise StudyError(f"{path}: damaged iteration record ({exc})") from None
        if records and records[-1].names != self.study.parameter_names:
            raise StudyError(
                f"{self.out}: the trail identifies {records[-1].names} but the study now lists "
                f"{self.study.parameter_names}; use a new --out folder"
            )
        # an iteration interrupted before its record.json is redone from scratch
        stale = self.iteration_dir(len(records) + 1)
        if stale.exists():
            shutil.rmtree(stale)
        return records

    def next_levels(self, record: IterationRecord) -> dict[str, list[float]]:
        """Levels for the iteration after ``record``: its ``next_levels.toml``, as edited."""
        path = self.iteration_dir(record.index) / "next_levels.toml"
        if not path.exists():
            return record.decision.next_levels()
        try:
            doc = tomllib.loads(path.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as exc:
            raise StudyError(f"{path}: not valid TOML: {exc}") from None
        table = doc.get("levels")
        if not isinstance(table, dict):
            raise StudyError(f"{path}: needs a [levels] table")
        names = self.study.parameter_names
        unknown = sorted(set(table) - set(names))
        missing = sorted(set(names) - set(table))
        if unknown or missing:
            raise StudyError(
                f"{path}: [levels] must list exactly the study parameters; "
                f"unknown {unknown}, missing {missing}"
            )
        bounds = self.study.bounds()
        levels: dict[str, list[float]] = {}
        for n in names:
            vals = table[n]
            if not isinstance(vals, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals
            ):
                raise StudyError(f"{path}: {n} must be a list of numbers, got {vals!r}")
            vals = sorted(float(v) for v in vals)
            if len(vals) < 2 or len(set(vals)) != len(vals) or not all(map(math.isfinite, vals)):
                raise StudyError(f"{path}: {n} needs at least 2 distinct finite levels, got {vals}")
            lo, hi = bounds[n]
            if vals[0] < lo or vals[-1] > hi:
                raise StudyError(f"{path}: {n} levels {vals} leave the bounds [{lo}, {hi}]")
            levels[n] = vals
        return levels

    def write_iteration(self, rec: IterationRecord, evaluator: Evaluator | None) -> None:
        """Write every file of a finished iteration; ``record.json`` last."""
        from tsid_fmu import report

        d = self.iteration_dir(rec.index)
        d.mkdir(parents=True, exist_ok=True)
        levels_csv = "parameter," + ",".join(
            f"level {i + 1}" for i in range(max(len(v) for v in rec.levels.values()))
        )
        lines = [levels_csv] + [
            n + "," + ",".join(repr(float(v)) for v in rec.levels[n]) for n in rec.names
        ]
        atomic_write(d / "levels.csv", "\n".join(lines) + "\n")
        atomic_write(d / "runs.csv", rec.runs_frame().to_csv(index=False))
        atomic_write(d / "response.csv", rec.response.to_pandas().to_csv())
        atomic_write(d / "anova.csv", rec.anova.to_pandas().to_csv())
        atomic_write(d / "decision.json", json.dumps(rec.decision.to_dict(), indent=2) + "\n")
        header = (
            f"# Levels proposed for iteration {rec.index + 1} ({rec.decision.message}).\n"
            "# Edit them if your judgement differs, then continue with:"
            " tsid identify STUDY --out DIR --resume\n"
        )
        body = "[levels]\n" + "".join(
            f"{p.name} = {_fmt_list(p.levels)}  # {p.case}: {p.reason}\n"
            for p in rec.decision.parameters
        )
        rerun = rec.extra.get("next")
        if rerun is not None:
            header = (
                f"# Levels for iteration {rec.index + 1}: {rerun['note']}.\n"
                "# Edit them if your judgement differs, then continue with:"
                " tsid identify STUDY --out DIR --resume\n"
            )
            body = "[levels]\n" + "".join(
                f"{n} = {_fmt_list(v)}\n" for n, v in rerun["levels"].items()
            )
        atomic_write(d / "next_levels.toml", header + body)
        if evaluator is not None:
            report.main_effects_plot(rec, d / "main_effects.png")
            # a plot is not part of the identification: its simulation is not counted,
            # so a resumed study (which does not redraw old plots) counts the same
            counted = evaluator.nfev
            simulated = evaluator.simulate_clean(rec.best_x)
            evaluator.nfev = counted
            report.fit_plot(simulated, d / "fit.png", title=f"Iteration {rec.index}: best so far")
        atomic_write(d / "record.json", json.dumps(rec.to_dict(), indent=1) + "\n")

    def canonical_records(self) -> list[Any]:
        """Return the complete canonical-factor iterations in the folder (for a resume)."""
        from tsid_fmu.canonical import CanonicalRecord

        records = []
        index = 1
        while (path := self.out / f"canonical_{index:02d}" / "record.json").exists():
            try:
                records.append(CanonicalRecord.from_dict(json.loads(path.read_text())))
            except (ValueError, KeyError, TypeError) as exc:
                raise StudyError(f"{path}: damaged canonical iteration record ({exc})") from None
            index += 1
        return records

    def clear_canonical(self, keep: int = 0) -> None:
        """Delete the canonical-factor iterations after the first ``keep``."""
        for d in sorted(self.out.glob("canonical_*")):
            suffix = d.name.removeprefix("canonical_")
            if d.is_dir() and suffix.isdigit() and int(suffix) > keep:
                shutil.rmtree(d)

    def write_canonical(self, rec: Any) -> None:
        """Write a canonical-factor iteration: ``canonical_NN/runs.csv`` and ``record.json``."""
        d = self.out / f"canonical_{rec.index:02d}"
        d.mkdir(parents=True, exist_ok=True)
        atomic_write(d / "runs.csv", rec.runs_frame().to_csv())
        atomic_write(d / "record.json", json.dumps(rec.to_dict(), indent=1) + "\n")

    def write_result(self, result: IdentificationResult, simulated: Any | None) -> None:
        """Write the final result files, report and plots."""
        from tsid_fmu import report

        report.write_outputs(result, self.out, simulated)
