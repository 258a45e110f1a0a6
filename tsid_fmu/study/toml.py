"""Study files: read the TOML form of a study (:mod:`tsid_fmu.study.toml_write` writes it).

:func:`read_study_file` turns a study file into the keyword arguments of
:class:`~tsid_fmu.study.definition.Study` (its parts already built and checked);
:func:`write_study_file` writes them back. Every key is checked on reading: a misspelt
key, a wrong type, a value out of range is a :class:`~tsid_fmu.errors.StudyError` that
names the file and the key. Booleans and strings are never taken as numbers.
"""

from __future__ import annotations

import difflib
import math
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.errors import StudyError
from tsid_fmu.study.checks import parse_toml
from tsid_fmu.study.choice import Choice, ModelChoice
from tsid_fmu.study.designopts import DesignOptions
from tsid_fmu.study.schema import ContributionOptions, Experiment, Method, Parameter, Phase
from tsid_fmu.study.toml_write import write_study_file

__all__ = [
    "design_options",
    "read_design",
    "read_study_file",
    "study_from_document",
    "write_study_file",
]


MAX_FILE_BYTES = 16 * 1024**2
"""Largest study file read."""

_TOP = {
    "study",
    "data",
    "experiments",
    "method",
    "leveling",
    "parameters",
    "phases",
    "contribution",
    "design",
}
_STUDY = {"name", "fmu", "start_values", "interface", "step_size"}
_DATA = {
    "file",
    "name",
    "time",
    "derived",
    "inputs",
    "outputs",
    "weights",
    "start_values",
    "sample_time",
    "role",
    "hold",
    "noise",
    "windows",
    "warmup",
    "window_weights",
    "initial",
}
_PARAM = {"levels", "min", "max", "unit", "choices", "fmus", "per_experiment"}
_PHASE = {"name", "parameters", "experiments", "array", "max_iterations"}
_METHOD_TYPES: dict[str, type] = {
    "array": str,
    "cost": str,
    "weighting": str,
    "replicates": int,
    "input_noise": float,
    "seed": int,
    "max_iterations": int,
    "max_simulations": int,
    "selection": str,
    "rotate": bool,
    "max_reruns": int,
    "refine": str,
    "refine_max_nfev": int,
    "start": str,
    "interface": str,
    "step": float,
    "tolerance": float,
    "cs_tolerance": float,
    "fidelity": bool,
    "uncertainty": str,
    "uncertainty_replicates": int,
}
_LEVELING_TYPES: dict[str, type] = {
    "significance_db": float,
    "tolerance": float,
    "shrink": float,
    "n_levels": int,
    "refine": bool,
    "selective": bool,
    "scale": str,
    "log_ratio": float,
    "min_contribution": float,
    "expand": float,
    "stall": int,
    "stall_rtol": float,
}
_CONTRIB_TYPES: dict[str, type] = {
    "enabled": bool,
    "group_ratio": float,
    "min_percent": float,
    "values": dict,
    "compare_ungrouped": bool,
    "refine_jointly": bool,
    "refine_span": float,
}
_DESIGN_TYPES: dict[str, type] = {
    "inputs": dict,
    "band": list,
    "duration": float,
    "sample_time": float,
    "kinds": list,
    "criterion": str,
    "bands": int,
    "seed": int,
    "experiment": str,
}
_TYPE_NAMES = {
    float: "a number",
    int: "an integer",
    str: "a string",
    bool: "true or false",
    list: "a list",
    dict: "a table",
}


class _Where:
    """The file being read, for messages."""

    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, label: str, message: str) -> StudyError:
        return StudyError(f"{self.source}: {label}{' ' if label else ''}{message}")


def _check_keys(table: Mapping[str, Any], allowed: set[str], where: _Where, label: str) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), sorted(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise where.error(
                "", f"unknown key {key!r} in {label}{hint} (allowed: {', '.join(sorted(allowed))})"
            )


def _table(doc: Mapping[str, Any], key: str, where: _Where, required: bool = False) -> dict:
    value = doc.get(key)
    if value is None:
        if required:
            raise where.error("", f"missing table [{key}]")
        return {}
    if not isinstance(value, dict):
        raise where.error("", f"[{key}] must be a table, got {type(value).__name__}")
    return value


def _ok(value: Any, kind: type) -> bool:
    if kind is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


def _get(
    table: Mapping[str, Any], key: str, kind: type, where: _Where, label: str, default: Any = None
) -> Any:
    if key not in table:
        return default
    value = table[key]
    if not _ok(value, kind):
        raise where.error(
            label, f"{key} must be {_TYPE_NAMES.get(kind, kind.__name__)}, got {value!r}"
        )
    return float(value) if kind is float else value


def _typed(table: Mapping[str, Any], types: dict[str, type], where: _Where, label: str) -> dict:
    _check_keys(table, set(types), where, label)
    return {k: _get(table, k, types[k], where, label) for k in table}


def _map(table: Mapping[str, Any], key: str, kind: type, where: _Where, label: str) -> dict:
    value = table.get(key, {})
    if not isinstance(value, dict) or not all(_ok(v, kind) for v in value.values()):
        what = "strings" if kind is str else "numbers"
        raise where.error(label, f"{key} must be a table of {what}, got {value!r}")
    return {k: (float(v) if kind is float else v) for k, v in value.items()}


def _build(where: _Where, label: str, make: Any, *args: Any, **kwargs: Any) -> Any:
    """Call a part's constructor; its StudyError gains the file and the table."""
    try:
        return make(*args, **kwargs)
    except StudyError as exc:
        raise where.error(label, str(exc)) from None


def _experiment(e: Mapping[str, Any], base: Path, where: _Where, label: str, i: int) -> Experiment:
    _check_keys(e, _DATA, where, label)
    file = _get(e, "file", str, where, label)
    if file is None:
        raise where.error(label, "is missing the key 'file'")
    path = (Path(file) if Path(file).is_absolute() else (base / file)).resolve()
    outputs = _map(e, "outputs", str, where, label)
    if not outputs:
        raise where.error(label, 'needs outputs = { FMU_VARIABLE = "column" }')
    return _build(
        where,
        label,
        Experiment,
        data=path,
        inputs=_map(e, "inputs", str, where, label),
        outputs=outputs,
        name=_get(e, "name", str, where, label, path.stem or f"exp{i + 1}"),
        time_column=_get(e, "time", str, where, label, "time"),
        derived=_map(e, "derived", str, where, label),
        weights=_map(e, "weights", float, where, label) if "weights" in e else None,
        start_values=_map(e, "start_values", float, where, label),
        sample_time=_get(e, "sample_time", float, where, label),
        role=_get(e, "role", str, where, label, "identify"),
        hold=_map(e, "hold", str, where, label),
        noise=_map(e, "noise", float, where, label),
        # checked by Experiment (numbers, pairs, order), whose messages name the key
        windows=e.get("windows", []),
        warmup=e.get("warmup", 0.0),
        window_weights=e.get("window_weights"),
        initial=_map(e, "initial", str, where, label),
    )


def _experiments(doc: Mapping[str, Any], base: Path, where: _Where) -> list[Experiment]:
    if "data" in doc and "experiments" in doc:
        raise where.error("", "give either [data] or [[experiments]], not both")
    if "data" in doc:
        return [_experiment(_table(doc, "data", where, True), base, where, "[data]", 0)]
    raw = doc.get("experiments")
    if not isinstance(raw, list) or not raw or not all(isinstance(e, dict) for e in raw):
        raise where.error("", "needs a [data] table or one or more [[experiments]]")
    return [_experiment(e, base, where, f"[[experiments]] #{i + 1}", i) for i, e in enumerate(raw)]


def _model_choice(
    name: str, spec: Mapping[str, Any], base: Path, where: _Where, label: str
) -> ModelChoice:
    extra = sorted(set(spec) - {"fmus"})
    if extra:
        raise where.error(
            label, f"gives fmus and {', '.join(extra)}: a choice among FMU files has fmus only"
        )
    files = _get(spec, "fmus", list, where, label)
    if not all(isinstance(f, str) and f for f in files):
        raise where.error(label, f"fmus must be a list of FMU file names, got {files!r}")
    paths = [Path(f) if Path(f).is_absolute() else (base / f).resolve() for f in files]
    for f, path in zip(files, paths, strict=True):
        if not path.is_file():
            raise where.error(label, f"fmus: no such file {f!r} ({path})")
    return _build(where, "", ModelChoice, name=name, choices=paths)


def _choice(name: str, spec: Mapping[str, Any], where: _Where, label: str) -> Choice:
    extra = sorted(set(spec) - {"choices"})
    if extra:
        raise where.error(
            label, f"gives choices and {', '.join(extra)}: a discrete factor has choices only"
        )
    return _build(where, "", Choice, name=name, choices=_get(spec, "choices", list, where, label))


def _parameters(doc: Mapping[str, Any], base: Path, where: _Where) -> list[Parameter | Choice]:
    out: list[Parameter | Choice] = []
    for name, spec in _table(doc, "parameters", where, True).items():
        label = f"[parameters] {name}"
        if not isinstance(spec, dict):
            raise where.error(
                label, f"must be a table such as {{ levels = [1, 2, 3] }}, got {spec!r}"
            )
        _check_keys(spec, _PARAM, where, label)
        if "choices" in spec:
            out.append(_choice(name, spec, where, label))
            continue
        if "fmus" in spec:
            out.append(_model_choice(name, spec, base, where, label))
            continue
        levels = _get(spec, "levels", list, where, label)
        if levels is None:
            raise where.error(label, "is missing the key 'levels'")
        out.append(
            _build(
                where,
                "",
                Parameter,
                name=name,
                levels=levels,
                min=_get(spec, "min", float, where, label, -math.inf),
                max=_get(spec, "max", float, where, label, math.inf),
                unit=_get(spec, "unit", str, where, label, ""),
                per_experiment=_get(spec, "per_experiment", bool, where, label, False),
            )
        )
    return out


def _phases(doc: Mapping[str, Any], where: _Where) -> list[Phase]:
    raw = doc.get("phases", [])
    if not isinstance(raw, list) or not all(isinstance(p, dict) for p in raw):
        raise where.error("", "phases must be given as [[phases]] tables")
    phases = []
    for i, ph in enumerate(raw):
        label = f"[[phases]] #{i + 1}"
        _check_keys(ph, _PHASE, where, label)
        plist = _get(ph, "parameters", list, where, label, None)
        if plist is None:
            raise where.error(label, "is missing the key 'parameters'")
        elist = _get(ph, "experiments", list, where, label, [])
        if not all(isinstance(x, str) for x in plist + elist):
            raise where.error(label, "parameters and experiments must be names")
        phases.append(
            Phase(
                parameters=plist,
                experiments=elist,
                name=_get(ph, "name", str, where, label, ""),
                array=_get(ph, "array", str, where, label),
                max_iterations=_get(ph, "max_iterations", int, where, label),
            )
        )
    return phases


def _method(doc: Mapping[str, Any], where: _Where) -> Method:
    args = _typed(_table(doc, "method", where), _METHOD_TYPES, where, "[method]")
    lev = _typed(_table(doc, "leveling", where), _LEVELING_TYPES, where, "[leveling]")
    leveling = _build(where, "[leveling]", LevelingOptions, **lev)
    return _build(where, "[method]", Method, **args, leveling=leveling)


def _contribution(doc: Mapping[str, Any], where: _Where) -> ContributionOptions:
    table = _table(doc, "contribution", where)
    args = _typed(table, _CONTRIB_TYPES, where, "[contribution]")
    values = args.get("values", {})
    if not all(isinstance(v, list) and all(_ok(x, float) for x in v) for v in values.values()):
        raise where.error("[contribution]", "values must map names to lists of numbers")
    args["values"] = {k: [float(x) for x in v] for k, v in values.items()}
    args.setdefault("enabled", bool(table))
    return _build(where, "[contribution]", ContributionOptions, **args)


def design_options(doc: Mapping[str, Any], source: str) -> DesignOptions:
    """Return the ``[design]`` table of a parsed study file (defaults where it is absent)."""
    where = _Where(source)
    args = _typed(_table(doc, "design", where), _DESIGN_TYPES, where, "[design]")
    # DesignOptions names its keys "[design] ...": no second "[design]"
    return _build(where, "", DesignOptions, **args)


def read_design(path: str | Path) -> DesignOptions:
    """Read the ``[design]`` table of a study file (:mod:`tsid_fmu.study.designopts`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{path}: cannot read the study file ({type(exc).__name__})") from None
    return design_options(parse_toml(text, str(path)), str(path))


def study_from_document(doc: Mapping[str, Any], base: Path, source: str) -> dict[str, Any]:
    """Return the keyword arguments of a Study from a parsed TOML document.

    Parameters
    ----------
    doc : mapping
        The parsed document.
    base : Path
        Folder that relative paths in the document are relative to.
    source : str
        The file name, for messages.
    """
    where = _Where(source)
    _check_keys(doc, _TOP, where, "the top level")
    params = doc.get("parameters")
    fmus = isinstance(params, dict) and any(
        isinstance(v, dict) and "fmus" in v for v in params.values()
    )  # a choice among FMU files names the files: [study] may be left out
    st = _table(doc, "study", where, required=not fmus)
    _check_keys(st, _STUDY, where, "[study]")
    parameters = _parameters(doc, base, where)
    design_options(doc, source)  # checked with the rest; tsid design reads it
    fmu_name = _get(st, "fmu", str, where, "[study]")
    models = [c for c in parameters if isinstance(c, ModelChoice)]
    if fmu_name is None and not models:
        raise where.error("[study]", "is missing the key 'fmu'")
    if fmu_name is None:  # a choice among FMU files: the first variant's description
        fmu = models[0].paths[0]
    else:
        fmu = Path(fmu_name) if Path(fmu_name).is_absolute() else (base / fmu_name).resolve()
    if not fmu.is_file():
        raise where.error("[study]", f"fmu: no such file {fmu}")
    return {
        "fmu": fmu,
        "parameters": parameters,
        "experiments": _experiments(doc, base, where),
        "method": _method(doc, where),
        "start_values": _map(st, "start_values", float, where, "[study]"),
        "interface": _get(st, "interface", str, where, "[study]", "auto"),
        "step_size": _get(st, "step_size", float, where, "[study]"),
        # the study file's name where the FMU is one of several variants
        "name": _get(st, "name", str, where, "[study]", Path(source).stem if models else fmu.stem),
        "phases": _phases(doc, where),
        "contribution": _contribution(doc, where),
    }


def read_study_file(path: Path) -> dict[str, Any]:
    """Read a study file and return the keyword arguments of a Study (see module doc)."""
    try:
        if not stat.S_ISREG(path.stat().st_mode):  # a device or pipe is never read to its end
            raise StudyError(f"{path}: the study file is not a regular file")
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)  # bounded, whatever stat says
        if len(raw) > MAX_FILE_BYTES:
            raise StudyError(f"{path}: the study file is larger than {MAX_FILE_BYTES} bytes")
        # as read_text did (universal newlines); a byte order mark (Notepad) is dropped
        text = raw.decode("utf-8-sig").replace("\r\n", "\n").replace("\r", "\n")
    except FileNotFoundError:
        raise StudyError(f"{path}: study file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{path}: cannot read the study file ({type(exc).__name__})") from None
    doc = parse_toml(text, str(path))
    return study_from_document(doc, path.parent, str(path))
