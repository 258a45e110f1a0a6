"""Read a finished study's results folder back into an :class:`IdentificationResult`.

``tsid identify --out DIR`` (or :func:`tsid_fmu.identify`) leaves ``DIR/result.json``
and the audit trail; :func:`load` turns them back into the object ``identify``
returned, so that a run from the shell can be studied in a notebook::

    res = tsid_fmu.load("results")
    res.params, res.fun, res.to_pandas(), res.plot_convergence()

Nothing is trusted unchecked: ``result.json``, every ``stage.json`` and every
iteration's ``record.json`` carry a digest, and the records the hashes of their
files (:mod:`tsid_fmu.trail.integrity`); a file changed or damaged since tsid-fmu
wrote it is a :class:`~tsid_fmu.errors.StudyError` naming it.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.result import EXTRA_KEYS, IdentificationResult
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.study.definition import Study
from tsid_fmu.study.toml import study_from_document
from tsid_fmu.trail.files import read_json
from tsid_fmu.trail.integrity import sha256_file, unseal
from tsid_fmu.trail.owner import FINGERPRINT, differences, fingerprint, read_fingerprint
from tsid_fmu.trail.reader import read_stage
from tsid_fmu.uncertainty.intervals import Uncertainty
from tsid_fmu.uncertainty.sampled import Sampled

__all__ = ["load", "study_changes"]

_OLD = (
    "result.json has no checksum (an older tsid-fmu wrote it, or the checksum was "
    "removed): its content is not verified; a checksum detects damage and careless edits, "
    "not a forger"
)


def _number(value: Any) -> float:
    """Return a float of result.json (``null`` stands for a non-finite one)."""
    return math.nan if value is None else float(value)


def _numbers(values: Any) -> dict[str, float]:
    return {str(k): _number(v) for k, v in (values or {}).items()}


def _uncertainty(data: Mapping[str, Any] | None) -> Uncertainty | None:
    if not data:
        return None
    known = {f.name for f in dataclasses.fields(Uncertainty)}
    kwargs = {k: v for k, v in data.items() if k in known}
    for key in ("values", "std_error", "relative", "cramer_rao", "resolution"):
        kwargs[key] = _numbers(kwargs.get(key))
    # strict JSON writes an infinite standard error as null: a parameter whose interval
    # is open had one (not determined), as the fresh result says, not nan (not computed)
    open_ended = {n for n, iv in (kwargs.get("intervals") or {}).items() if iv and None in iv}
    for key in ("std_error", "relative"):
        for n in open_ended:
            if math.isnan(kwargs[key].get(n, 0.0)):
                kwargs[key][n] = math.inf
    for key in ("condition", "inflation"):
        if key in kwargs:
            kwargs[key] = _number(kwargs[key])
    return Uncertainty(**kwargs)


def _stage_dirs(out: Path, summaries: list[Mapping[str, Any]]) -> list[Path]:
    """Return each stage's folder, in the order of result.json (``search/pipeline.py``)."""
    dirs, phases = [], 0
    for s in summaries:
        kind = s.get("kind")
        folder = (s.get("extra") or {}).get("folder")
        if kind == StageKind.PHASE:
            phases += 1
        if isinstance(folder, str) and _inside(folder):  # written by the trail
            dirs.append(out / folder if folder else out)
        elif kind == StageKind.PHASE:
            dirs.append(out / f"phase_{phases:02d}")
        elif kind in ("contribution", "refinement"):
            dirs.append(out / str(kind))
        else:
            dirs.append(out)
    return dirs


def _inside(folder: str) -> bool:
    """Whether a stage's folder is a plain relative path inside the results folder."""
    parts = Path(folder).parts
    return not Path(folder).is_absolute() and all(p not in ("..", ".") for p in parts)


def _stages(out: Path, summaries: list[Mapping[str, Any]]) -> list[StageResult]:
    """Each stage with its iterations, from the trail; it must agree with result.json."""
    stages = []
    for summary, folder in zip(summaries, _stage_dirs(out, summaries), strict=True):
        stage = read_stage(folder)
        if stage is None:
            raise StudyError(
                f"{folder / 'stage.json'}: missing, but result.json lists the stage "
                f"{summary.get('name')!r}; restore it, or run the study again"
            )
        if stage.name != summary.get("name") or len(stage.records) != summary.get("iterations"):
            raise StudyError(
                f"{folder}: the trail does not match result.json (stage {summary.get('name')!r}"
                f" with {summary.get('iterations')} iterations); the folder was changed after "
                "the study finished"
            )
        stages.append(stage)
    return stages


def _read(out: Path) -> tuple[dict[str, Any], list[str]]:
    """Return result.json's content, checked, and the warnings about it."""
    path = out / "result.json"
    if not out.is_dir():
        raise StudyError(f"{out}: no such folder")
    if not path.is_file():
        raise StudyError(
            f"{out}: no result.json; not the folder of a finished study (a paused one "
            "writes none: continue it with resume=True)"
        )
    data = read_json(path, "result")
    if not isinstance(data, dict):
        raise StudyError(f"{path}: damaged result (not a JSON object)")
    if "digest" not in data:
        return data, [_OLD]
    advice = "run the study again, or restore the file from a copy"
    return unseal(data, path, "result", advice), []


def _kept(extra: Any) -> dict[str, Any]:
    """Return the attributes ``result.json`` keeps under ``"extra"`` (:data:`EXTRA_KEYS`)."""
    if not isinstance(extra, Mapping):
        raise TypeError(f"'extra' is {type(extra).__name__}, not an object")
    return {k: dict(extra[k]) for k in EXTRA_KEYS if extra.get(k) is not None}


def _jacobian(out: Path, entry: Any) -> np.ndarray | None:
    """Return the Jacobian result.json names (``jac``: file, shape, SHA-256), checked.

    Raises
    ------
    StudyError
        The entry is damaged, or the file is missing, changed since tsid-fmu wrote it
        (its SHA-256 differs) or not the array result.json describes.
    """
    if entry is None:
        return None
    advice = "restore it from a copy, or run the study again"
    try:
        name, shape, digest = str(entry["file"]), [int(n) for n in entry["shape"]], entry["sha256"]
    except (KeyError, TypeError, ValueError):
        raise StudyError(f"{out / 'result.json'}: damaged result (its 'jac' entry)") from None
    path = out / Path(name).name
    try:
        same = sha256_file(path) == digest
    except OSError:
        raise StudyError(f"{path}: missing, but result.json lists it; {advice}") from None
    if not same:
        raise StudyError(
            f"{path}: changed or damaged since tsid-fmu wrote it (its SHA-256 differs from "
            f"the one in result.json); {advice}"
        )
    try:
        jac = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise StudyError(f"{path}: damaged Jacobian ({type(exc).__name__}); {advice}") from None
    if list(jac.shape) != shape or jac.dtype != np.float64:
        raise StudyError(f"{path}: not the {shape} array of floats result.json describes")
    return jac


def _copied_study(out: Path, folder: Any) -> Study:
    """Return the study of the folder's ``study.toml``, its paths read from ``folder``.

    ``study.toml`` is the study file as run, copied: its relative paths start at the
    folder the original was in (``study_folder`` in result.json).
    """
    path = out / "study.toml"
    if not path.is_file() or not isinstance(folder, str):
        raise StudyError(f"{out}: no study.toml, or result.json does not say where it was")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise StudyError(f"{path}: cannot read the study ({type(exc).__name__})") from None
    return Study(**study_from_document(doc, Path(folder), str(path)), source=path)


def _study(
    out: Path, study: Study | str | Path | None, folder: Any
) -> tuple[Study | None, list[str]]:
    """Return the study to attach, and a warning where there is none or it changed."""
    if study is None:
        try:
            study = _copied_study(out, folder)
        except StudyError as exc:
            return None, [f"the study is not attached ({exc}); pass study= to load()"]
    elif not isinstance(study, Study):
        study = Study.from_toml(study)
    return study, study_changes(out, study)


def study_changes(out_dir: str | Path, study: Study) -> list[str]:
    """Return the warning that ``study`` or its files changed since the run in ``out_dir``.

    Empty where they are those of the run (its ``fingerprint.json``); the warning
    :func:`load` gives otherwise (``tsid design`` repeats it).
    """
    try:
        changed = differences(read_fingerprint(Path(out_dir) / FINGERPRINT), fingerprint(study))
    except StudyError as exc:
        return [str(exc)]
    if changed:
        shown = "; ".join(changed[:4]) + (" ..." if len(changed) > 4 else "")
        return [f"the study or its files changed since this run: {shown}"]
    return []


def load(out_dir: str | Path, study: Study | str | Path | None = None) -> IdentificationResult:
    """Return the :class:`IdentificationResult` of a finished study's results folder.

    Parameters
    ----------
    out_dir : path
        The folder ``tsid identify --out`` (or ``identify(study, out)``) wrote.
    study : Study or path, optional
        The study, to attach (units, plots, ``parameters_frame``); default the folder's
        ``study.toml`` (the study file as run), else none. A warning says where none
        is attached, or where the study or its FMU and data files differ from those
        of the run (its ``fingerprint.json``).

    Returns
    -------
    IdentificationResult
        ``params`` (with ``x``, ``names`` and ``cov``), ``fun``, ``nfev``, ``status``,
        the stages with their iterations, the intervals and uncertainty, fit, noise,
        validation and warnings as ``identify`` returned them, with ``out_dir`` set;
        ``jac`` the same array, read from ``jacobian.npy`` (``None`` where the run
        computed no intervals, and for a folder of a tsid-fmu that did not write it).

    Raises
    ------
    StudyError
        No such folder, no ``result.json`` (a paused or interrupted study), or a file
        of the folder changed or damaged since tsid-fmu wrote it.
    """
    out = Path(out_dir)
    data, warnings = _read(out)
    attached, more = _study(out, study, data.get("study_folder"))
    try:
        result = IdentificationResult(
            params=_params(data),
            fun=_number(data["fun"]),
            nfev=int(data["nfev"]),
            success=bool(data["success"]),
            status=int(data["status"]),
            message=str(data["message"]),
            nit=int(data.get("nit", 0)),
            account=[str(line) for line in data.get("account") or []],
            stages=_stages(out, list(data.get("stages") or [])),
            intervals={str(k): list(v) for k, v in (data.get("intervals") or {}).items()},
            uncertainty=_uncertainty(data.get("uncertainty")),
            sampled=Sampled.from_dict(data["sampled"]) if data.get("sampled") else None,
            fit=dict(data.get("fit") or {}),
            noise=dict(data.get("noise") or {}),
            noise_source=dict(data.get("noise_source") or {}),
            validation=dict(data.get("validation") or {}),
            weak=dict(data.get("weak") or {}),
            warnings=[*map(str, data.get("warnings") or []), *warnings, *more],
            **_kept(data.get("extra") or {}),
            comparison=data.get("comparison"),
            study=attached,
            out_dir=out,
            structures=[dict(r) for r in data.get("structures") or []],
            jac=_jacobian(out, data.get("jac")),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise StudyError(f"{out / 'result.json'}: damaged result ({exc!r})") from None
    result.describe_parameters()
    result.contribution = {
        n: [float(r.anova.contribution[n]) for r in result.iterations if n in r.names]
        for n in result.params
    }
    return result


def _params(data: dict[str, Any]) -> dict[str, float]:
    """Return the values by name: ``params``, else the ``x`` by name of tsid-fmu 0.2."""
    if "params" in data:
        return _numbers(data["params"])
    return _numbers(data["x"])
