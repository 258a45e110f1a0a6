"""Study files: write a study's fields as TOML that :mod:`tsid_fmu.study.toml` reads back.

Paths are written relative to the file's folder; data given as DataFrames are written
as CSV files beside it; only the fields that differ from their defaults are written.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.errors import StudyError
from tsid_fmu.study.choice import ModelChoice
from tsid_fmu.study.schema import Experiment

__all__ = ["write_study_file"]


def _relative(path: Path, base: Path) -> str:
    path = Path(path).resolve()
    try:
        return os.path.relpath(path, base).replace(os.sep, "/")
    except ValueError:  # another drive on Windows
        return str(path)


def _non_default(obj: Any, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """Fields of a dataclass that differ from their defaults (None values dropped).

    Fields named in ``skip`` are left out (an experiment's data, which may be a
    DataFrame, is written on its own).
    """
    out = {}
    for f in dataclasses.fields(obj):
        if f.name in skip:
            continue
        value = getattr(obj, f.name)
        default = (
            f.default
            if f.default is not dataclasses.MISSING
            else (
                f.default_factory() if f.default_factory is not dataclasses.MISSING else None  # type: ignore[misc]
            )
        )
        if value is not None and value != default:
            out[f.name] = value
    return out


def _experiment_table(e: Experiment, base: Path, stem: str) -> dict[str, Any]:
    if isinstance(e.data, str | os.PathLike):
        file = _relative(Path(e.data), base)
    else:  # a DataFrame: written beside the study file
        name = f"{stem}_{''.join(c if c.isalnum() else '_' for c in e.name)}.csv"
        e.data.to_csv(base / name, index=False)
        file = name
    table: dict[str, Any] = {"file": file, "name": e.name}
    fields = _non_default(e, skip=("data",))
    for key, out in (
        ("time_column", "time"),
        ("inputs", "inputs"),
        ("outputs", "outputs"),
        ("derived", "derived"),
        ("weights", "weights"),
        ("hold", "hold"),
        ("start_values", "start_values"),
        ("sample_time", "sample_time"),
        ("role", "role"),
        ("noise", "noise"),
        ("windows", "windows"),
        ("warmup", "warmup"),
        ("window_weights", "window_weights"),
        ("initial", "initial"),
    ):
        if key in fields:
            table[out] = fields[key]
    return table


def _document(fields: Mapping[str, Any], base: Path, stem: str) -> dict[str, Any]:
    study: dict[str, Any] = {"name": fields["name"], "fmu": _relative(fields["fmu"], base)}
    for key in ("start_values", "interface", "step_size"):
        if fields[key] not in (None, {}, "auto"):
            study[key] = fields[key]
    method = _non_default(fields["method"])
    leveling = _non_default(method.pop("leveling", LevelingOptions()))
    params = {}
    for p in fields["parameters"]:
        spec: dict[str, Any] = {"levels": list(p.levels)}
        spec.update({k: v for k, v in (("min", p.min), ("max", p.max)) if math.isfinite(v)})
        if p.unit:
            spec["unit"] = p.unit
        if p.per_experiment:
            spec["per_experiment"] = True
        params[p.name] = spec
    for c in fields.get("choices") or []:
        if isinstance(c, ModelChoice):
            params[c.name] = {"fmus": [_relative(f, base) for f in c.paths]}
        else:
            params[c.name] = {"choices": list(c.choices)}
    doc: dict[str, Any] = {"study": study, "method": method}
    if leveling:
        doc["leveling"] = leveling
    doc["experiments"] = [_experiment_table(e, base, stem) for e in fields["experiments"]]
    doc["parameters"] = params
    if fields["phases"]:
        doc["phases"] = [
            _non_default(ph) | {"parameters": ph.parameters} for ph in fields["phases"]
        ]
    contribution = _non_default(fields["contribution"])
    if contribution:
        doc["contribution"] = contribution | {"enabled": fields["contribution"].enabled}
    return doc


def write_study_file(path: str | Path, fields: Mapping[str, Any]) -> Path:
    """Write a study's fields as a TOML file; return its path.

    Paths are written relative to the file's folder, which is made if it is missing;
    data given as DataFrames are written as ``<stem>_<experiment>.csv`` beside it.
    """
    import tomli_w

    path = Path(path)
    if path.is_dir():
        raise StudyError(f"{path}: is a folder; give the study file to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    base = path.parent.resolve()
    doc = _document(fields, base, path.stem)
    path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return path
