"""Reading a finished trail back without taking its folder: records and stages, checked.

:class:`~tsid_fmu.trail.folder.Trail` reads the same files to resume a study (under the
folder's lock, removing an interrupted iteration); these functions only read, so that
:func:`tsid_fmu.load` can open a results folder while nothing runs in it, or while
another process reads it too. Every file is checked against its digest and hashes
(:mod:`tsid_fmu.trail.integrity`) first.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from tsid_fmu.errors import StudyError
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult
from tsid_fmu.trail.files import read_json
from tsid_fmu.trail.integrity import unseal, verify_files

__all__ = ["read_record", "read_records", "read_stage"]


def read_record(
    path: Path, on_files: Callable[[Path, object], None] | None = None
) -> IterationRecord:
    """Return the iteration of a ``record.json``, after checking it and its files.

    ``on_files(folder, hashes)``, if given, sees the files the record lists (a resumed
    study notes the files in the folder that tsid-fmu did not write).

    Raises
    ------
    StudyError
        The record or a file it lists is missing, changed or damaged.
    """
    advice = f"restore it, or delete {path.parent} and the iterations after it to redo them"
    data = unseal(read_json(path, "iteration record"), path, "iteration record", advice)
    hashes = data.pop("files", None)
    verify_files(path.parent, hashes, path)
    if on_files is not None:
        on_files(path.parent, hashes)
    try:
        return IterationRecord.from_dict(data)
    except (KeyError, TypeError, ValueError) as exc:
        raise StudyError(f"{path}: damaged iteration record ({exc})") from None


def read_records(stage_dir: Path) -> list[IterationRecord]:
    """Return the complete iterations of a stage folder (``iteration_01/``, ...), in order."""
    records: list[IterationRecord] = []
    while (path := stage_dir / f"iteration_{len(records) + 1:02d}" / "record.json").exists():
        records.append(read_record(path))
    return records


def read_stage(stage_dir: Path, records: bool = True) -> StageResult | None:
    """Return the finished stage of ``stage_dir/stage.json`` (None if there is none).

    Parameters
    ----------
    stage_dir : Path
        The stage's folder (the output folder itself for a one-group study).
    records : bool
        Read its iterations too (:func:`read_records`).

    Raises
    ------
    StudyError
        ``stage.json`` or one of the iterations is changed or damaged.
    """
    path = stage_dir / "stage.json"
    if not path.exists():
        return None
    advice = "restore it, or delete it to finish the stage again"
    body = unseal(read_json(path, "stage record"), path, "stage record", advice)
    found = read_records(stage_dir) if records else []
    try:
        return StageResult.from_dict(body, found)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise StudyError(f"{path}: damaged stage record ({exc})") from None
