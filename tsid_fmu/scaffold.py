"""``tsid init``: write a commented study file from an FMU and a data file.

The FMU's model description gives the parameters (with start values, units, declared
bounds and descriptions), the inputs and the outputs; the data file gives the columns.
The study written:

- maps each FMU input and output to the data column of the same name, compared
  case-insensitively (also local variables, which a study may compare as outputs, and
  the derived channels given with ``--derived``); what is left unmatched is listed in
  comments. An input or output without a column that the columns look like once
  combined or differentiated gets a ``--derived`` proposal and the ``tsid init`` command
  that adds it (:func:`~tsid_fmu.scaffold_rules.derived_hints`: ``F_o`` from the load
  cells ``F_of`` and ``F_or`` as ``F_of - F_or``; ``v_o`` from ``x_o`` as ``der(x_o)``);
- identifies every real parameter with five levels around its start value: log-spaced
  over one decade (``start / sqrt(10)`` to ``start * sqrt(10)``), kept inside the
  ``min``/``max`` the FMU declares, which are written as the parameter's bounds (else
  ``min = 0`` for a positive start, ``max = 0`` for a negative one), with its unit;
- writes a parameter that the data should not decide commented out, with the reason, so
  that the FMU's value is kept (:func:`~tsid_fmu.scaffold_rules.held_reason`): a
  numerical setting rather than a physical parameter (a solver step such as Hopsan's
  ``timestep``, a tolerance, a threshold such as a velocity "below which the motor side
  is considered at rest", a regularisation), a constant of the medium or the
  environment (gravity, the ambient pressure and temperature, a resistor's reference
  temperature and temperature coefficient), a signal source's time (a ramp's start time
  and duration, a pulse's period); past :data:`MOST_FREE` free parameters, in the
  order the FMU declares them, the rest are written commented out too;
- screens what is left at the start values (:mod:`tsid_fmu.scaffold_screen`, ``2 p + 1``
  simulations) and writes commented out, with the reason, a parameter whose first
  levels move the outputs by less than the noise can show, or whose effect the free
  ones reproduce (a product's second factor);
- uses ``cost = "sse"``, ``weighting = "noise"``, ``replicates = 1`` and the smallest
  orthogonal array that fits.

The file runs as written: ``tsid identify study.toml``.
"""

from __future__ import annotations

import math
import os
import re
import shlex
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from tsid_fmu.data.measured import MeasuredData, load_data
from tsid_fmu.doe.arrays import COMPOSITION, select_array
from tsid_fmu.errors import StudyError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import (
    REAL_TYPES,
    VariableInfo,
    initial_state,
    parse_start,
    variable_info,
)
from tsid_fmu.scaffold_rules import bounded_levels, decade_levels, derived_hints, held_reason
from tsid_fmu.scaffold_screen import Screened, screen_start
from tsid_fmu.scaffold_text import _as_written, _initial_hint, _method_lines, _window_hint
from tsid_fmu.study.tomltext import comment_text, toml_key, toml_string

__all__ = ["decade_levels", "init_and_screen", "init_study"]


def _inline(mapping: Mapping[str, str]) -> str:
    return "{ " + ", ".join(f"{toml_key(k)} = {toml_string(v)}" for k, v in mapping.items()) + " }"


@dataclass
class _Match:
    inputs: dict[str, str]
    outputs: dict[str, str]
    locals: list[str]
    missing_inputs: list[str]
    missing_outputs: list[str]
    unused: list[str]


def _match(variables: Sequence[VariableInfo], columns: Sequence[str]) -> _Match:
    by_lower: dict[str, str] = {}
    for c in columns:
        by_lower.setdefault(c.lower(), c)
    used: set[str] = set()

    def pick(names: Sequence[str]) -> tuple[dict[str, str], list[str]]:
        found, missing = {}, []
        for n in names:
            col = by_lower.get(n.lower())
            if col is not None and col not in used:
                found[n] = col
                used.add(col)
            else:
                missing.append(n)
        return found, missing

    inputs, missing_in = pick([v.name for v in variables if v.causality == "input"])
    # an FMI 3 array output is no column: tsid compares scalars (a session refuses it)
    outputs, missing_out = pick(
        [v.name for v in variables if v.causality == "output" and not v.shape]
    )
    local_names = [v.name for v in variables if v.causality == "local" and v.type in REAL_TYPES]
    local_found, _ = pick(local_names)
    outputs.update(local_found)
    unused = [c for c in columns if c not in used]
    return _Match(inputs, outputs, list(local_found), missing_in, missing_out, unused)


def _number(x: float) -> str:
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _entry(v: VariableInfo, n: int = 5) -> tuple[str, bool, str]:
    """Return a parameter's TOML entry, whether bounds moved its levels, a bound's note.

    The note says where tsid chose a bound itself, from the start value's sign ("" if
    it did not).
    """
    start = parse_start(v)
    start = start if start is not None else 0.0
    low, high = v.min, v.max
    if low is not None and high is not None and low >= high:
        low = high = None  # bounds that contradict each other are no bounds
    levels = bounded_levels(start, low, high, n)
    own = ""
    if low is None and levels[0] >= 0 and start > 0:
        low, own = 0.0, "min = 0 is tsid's (the FMU declares none): delete it if it can be < 0"
    if high is None and levels[-1] <= 0 and start < 0:
        high, own = 0.0, "max = 0 is tsid's (the FMU declares none): delete it if it can be > 0"
    bounds = "".join(
        f", {key} = {_number(float(b))}"
        for key, b in (("min", low), ("max", high))
        if b is not None
    )
    unit = f", unit = {toml_string(v.unit)}" if v.unit else ""
    text = ", ".join(repr(x) for x in levels)
    entry = f"{toml_key(v.name)} = {{ levels = [{text}]{bounds}{unit} }}"
    return entry, levels != decade_levels(start, n), own


def _choice_line(v: VariableInfo) -> str:
    """Return a discrete parameter, commented out, with the ``choices`` it could take."""
    start = (v.start or "").strip()
    if v.type == "Boolean":
        hint, what = "[false, true]", "choose true or false from the data"
    elif v.items:
        hint = "[" + ", ".join(f'"{i}"' for i in v.items) + "]"
        what = "choose among its items from the data"
    else:
        first = int(float(start)) if start.lstrip("-").replace(".", "", 1).isdigit() else 0
        hint, what = f"[{first}, {first + 1}]", "list the values to compare"
    return (
        f"# {toml_key(v.name)} = {{ choices = {hint} }}  # {v.type} (start {start or 'none'}): "
        f"{what} (structure identification); uncomment to identify it, with [method] array "
        '= "L50" for one 2-level choice beside 5-level parameters (more choices: parameters '
        'of 3 levels and "L18" or "L36")'
    )


def _nothing_free(fmu: Path, variables: Sequence[VariableInfo]) -> str:
    """Say that an FMU has nothing ``init`` can free, and which states could be."""
    states = [v.name for v in variables if initial_state(v)]
    return f"{fmu}: no real parameter to identify, and every input has a data column" + (
        f"; initial states that could be identified: {', '.join(states)} "
        '(initial = { NAME = "identify" } in the study)'
        if states
        else ""
    )


def _refused(v: VariableInfo, n: int) -> str | None:
    """Return ``v``'s entry commented out with why a study cannot hold it, or None.

    A study refuses a parameter whose name is empty or holds control characters, and
    levels that are not ``n`` distinct finite numbers (a start value near the float
    range's ends, bounds closer than the levels' figures): rather than a study that
    ``tsid identify`` refuses, ``init`` writes the FMU's value kept, and why.
    """
    if not v.name or not v.name.isprintable():
        return (
            f"# {toml_key(v.name)}  # not written: a study's parameter name must be "
            "non-empty printable text; the FMU's value is kept"
        )
    start = parse_start(v)
    start = start if start is not None else 0.0
    low = v.min if v.min is not None and v.max is not None and v.min < v.max else None
    high = v.max if low is not None else None
    try:
        levels = bounded_levels(start, low, high, n)
        ok = len(set(levels)) == n and math.isfinite(levels[-1] - levels[0])
    except (ValueError, OverflowError, ZeroDivisionError):
        ok = False
    if ok:
        return None
    return (
        f"# {toml_key(v.name)}  # not written: no {n} distinct finite levels around its "
        f"start {v.start} within its min/max; the FMU's value is kept"
    )


MOST_FREE = 40
"""Parameters ``tsid init`` frees at most: the 40 three-level columns of L81.

The first 40 that no rule holds, in the order the FMU declares them, are free; the rest
are written commented out, to be screened (``tsid screen``) and swapped in by hand."""


def _parameter_lines(
    variables: Sequence[VariableInfo],
    n: int = 5,
    most: int = MOST_FREE,
    held: Sequence[str] = (),
    screened: Mapping[str, str] | None = None,
) -> tuple[list[str], int]:
    """Return the ``[parameters]`` lines with ``n`` levels each, and how many are free.

    ``held`` names inputs that no data column feeds: held at one value over each run,
    they are identified like parameters. ``screened`` holds what the screening found
    the data cannot decide, each with its reason
    (:func:`~tsid_fmu.scaffold_screen.screen_start`). Past ``most`` free parameters the
    rest are written commented out, with the reason.
    """
    screened = screened or {}
    lines, count = [], 0
    seen: set[str] = set()
    for v in variables:
        if v.name in seen and (v.name in held or v.causality == "parameter"):
            lines.append(f"# {toml_key(v.name)}  # not written: a second variable of this name")
            continue
        if v.name in held and v.type in REAL_TYPES and not v.shape:
            seen.add(v.name)
            refused = _refused(v, n)
            if refused is not None:
                lines.append(refused)
                continue
            entry, _, own = _entry(v, n)
            if v.name in screened:
                lines.append(f"# {entry}  # {screened[v.name]}: uncomment to identify it")
                continue
            note = "  # an input without a data column, held at one value over each run"
            lines.append(entry + note + (f"; {own}" if own else ""))
            count += 1
            continue
        if v.causality != "parameter" or v.variability not in ("fixed", "tunable"):
            continue
        seen.add(v.name)
        if v.type not in REAL_TYPES:
            lines.append(_choice_line(v))
            continue
        refused = _refused(v, n)
        if refused is not None:
            lines.append(refused)
            continue
        entry, bounded, own = _entry(v, n)
        reason = held_reason(v) or screened.get(v.name)
        if reason is not None:
            lines.append(
                f"# {entry}  # {reason}: the FMU's {v.start} is kept; uncomment to identify it"
            )
            continue
        if count >= most:
            lines.append(
                f"# {entry}  # beyond the {most} parameters the largest standard array "
                "hosts: the FMU's value is kept; screen them (tsid screen) and swap it in"
            )
            continue
        note = f"  # start {v.start}" + (" (levels within the FMU's min/max)" if bounded else "")
        note += (f": {v.description}" if v.description else "") + (f"; {own}" if own else "")
        lines.append(entry + note)
        count += 1
    return lines, count


def _derived_option(name: str, expression: str) -> str:
    text = f"{name}={expression}"
    return f'--derived "{text}"' if re.fullmatch(r'[^"$`\\]*', text) else shlex.quote(text)


def _hint_lines(
    paths: Sequence[str], derived: Mapping[str, str], hints: Mapping[str, str]
) -> list[str]:
    """Comments proposing ``--derived`` for the FMU inputs and outputs without a column."""
    lines = [
        f"# {name} has no column; if it is {expression}: {_derived_option(name, expression)}"
        for name, expression in hints.items()
    ]
    if hints:
        fmu, data, out = (shlex.quote(p) for p in paths)
        options = [_derived_option(k, e) for k, e in {**derived, **hints}.items()]
        # --force: the command rewrites this very file, which then exists
        lines.append(
            f"# to add them, run: tsid init {fmu} {data} -o {out} --force {' '.join(options)}"
        )
    return lines


def _header(fmu: Path, data: Path, m: _Match, time: str, derived: Mapping[str, str]) -> list[str]:
    lines = [
        f"# Study written by `tsid init` from {fmu.name} and {data.name}.",
        "# Check the levels and mappings, then run: tsid identify THIS_FILE --out DIR",
        "",
        "[study]",
        f"name = {toml_string(f'{fmu.stem} from {data.name}')}",
        f"fmu = {toml_string(fmu.as_posix())}",
        "",
        "[data]",
        f"file = {toml_string(data.as_posix())}",
        f"time = {toml_string(time)}",
    ]
    if derived:
        lines.append(f"derived = {_inline(derived)}")
    lines.append("# FMU variable = data column (matched by name, case-insensitively)")
    lines.append(f"inputs = {_inline(m.inputs)}")
    if m.missing_inputs:
        lines.append(f"# FMU inputs without a column (held at one value over each run, "
                     f"identified in [parameters]): {', '.join(m.missing_inputs)}")  # fmt: skip
    lines.append(f"outputs = {_inline(m.outputs)}")
    if m.locals:
        lines.append(f"# compared as outputs although local in the FMU: {', '.join(m.locals)}")
    if m.missing_outputs:
        lines.append(f"# FMU outputs without a column: {', '.join(m.missing_outputs)}")
    if m.unused:
        lines.append(f"# data columns not used: {', '.join(m.unused)}")
    return lines


def _write(
    out: Path,
    head: list[str],
    fmu: Path,
    variables: Sequence[VariableInfo],
    held: Sequence[str],
    screened: Mapping[str, str] | None,
    summary: str,
) -> str:
    """Write the study: ``head``, then the method and the parameters; return its text."""
    params, count = _parameter_lines(variables, held=held, screened=screened)
    if count == 0:
        raise StudyError(_nothing_free(fmu, variables))
    n = 5
    if count > COMPOSITION["L50"][5]:  # more than a five-level array hosts: three levels
        n = 3
        params, count = _parameter_lines(variables, n, held=held, screened=screened)
    array, _ = select_array([n] * count)
    lines = (
        head
        + _method_lines(array.name, count, n)
        + [
            "[parameters]",
            f"# {'five' if n == 5 else 'three'} log-spaced levels over one decade around the "
            "FMU's start value, within the",
            "# FMU's min/max; numerical settings (steps, tolerances, thresholds), constants of",
            "# the medium or the environment and signal sources' times commented out;",
            "# per_experiment = true in an entry identifies one value per experiment (reported",
            "# as NAME[EXPERIMENT]), such as each test's initial position or a sensor offset",
            *([f"# {summary}"] if summary else []),
            *params,
        ]
    )
    # what tsid copies into a comment (descriptions, names, columns) stays in it: a
    # newline there would start a line of TOML; in a TOML string the escapes mean the same
    text = "\n".join(comment_text(line) for line in lines) + "\n"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    return text


def init_study(
    fmu: str | os.PathLike[str],
    data: str | os.PathLike[str],
    out: str | os.PathLike[str],
    derived: Mapping[str, str] | None = None,
    *,
    screen: bool = True,
    workers: int | None = None,
    timeout: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> str:
    """Write a commented study file for ``fmu`` and ``data`` to ``out``; return its text.

    As :func:`init_and_screen`, without what the screening found.
    """
    return init_and_screen(
        fmu, data, out, derived, screen=screen, workers=workers, timeout=timeout,
        progress=progress,
    )[0]  # fmt: skip


def init_and_screen(
    fmu: str | os.PathLike[str],
    data: str | os.PathLike[str],
    out: str | os.PathLike[str],
    derived: Mapping[str, str] | None = None,
    *,
    screen: bool = True,
    workers: int | None = None,
    timeout: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[str, Screened | None]:
    """Write a commented study file for ``fmu`` and ``data`` to ``out``.

    Returns the file's text and what the screening found (None with ``screen=False``).

    With ``screen`` (the default) the candidates are screened at their start values,
    ``2 p + 1`` simulations (:func:`~tsid_fmu.scaffold_screen.screen_start`): those the
    data cannot see, or see only in combination with others, are written commented out
    with the reason. ``workers``, ``timeout`` and ``progress`` are the screening's, as
    for :func:`tsid_fmu.identify`. Where the screening cannot run, the study is written
    with every candidate free and says why.

    Raises
    ------
    StudyError
        No FMU output (or local variable) matches a data column, or no parameter is
        left to identify.
    FMUError, DataError
        The FMU or the data file cannot be read.
    """
    fmu, data, out = Path(fmu), Path(data), Path(out)
    md = read_fmu_description(fmu)
    variables = [variable_info(v) for v in md.modelVariables]
    time = _time_column(data)
    probe, first, last = _probe(data, time, derived)
    columns = [c for c in probe.names if c != time]
    match = _match(variables, columns)
    found = derived_hints(match.missing_outputs + match.missing_inputs, columns, match.unused)
    hints = _hint_lines([str(fmu), str(data), str(out)], derived or {}, found)
    if not match.outputs:
        outs = [comment_text(v.name) for v in variables if v.causality == "output"]
        shown = [comment_text(c) for c in columns]  # a newline in a name: no line of its own
        raise StudyError(
            f"{data}: no column matches an output of {fmu.name} ({', '.join(outs) or 'none'}); "
            f"columns: {', '.join(shown)}; add one, or give it with --derived NAME=EXPRESSION"
            + "".join(f"\n{comment_text(line.removeprefix('# '))}" for line in hints)
        )
    held = match.missing_inputs
    base = out.resolve().parent
    rel = {p: _as_written(p, base) for p in (fmu, data)}
    lines = _header(rel[fmu], rel[data], match, time, derived or {})
    lines += _window_hint(first, last)
    lines += _initial_hint([v.name for v in variables if initial_state(v)], match.outputs)
    lines += hints
    text = _write(out, lines, fmu, variables, held, None, "")  # on disk before any run
    if not screen:
        return text, None
    found = screen_start(out, workers=workers, timeout=timeout, progress=progress)
    if not found.failed and len(found.held) == len(found.effect):
        found.failed = "no candidate moves the outputs above the noise; check the mappings"
        found.held = {}
    return _write(out, lines, fmu, variables, held, found.held, found.summary()), found


SAMPLE_ROWS = 1000
"""Rows of a text data file that ``tsid init`` reads in full (the names, ``--derived``)."""


def _probe(
    data: Path, time: str, derived: Mapping[str, str] | None
) -> tuple[MeasuredData, float, float]:
    """Return the data's first rows, and the first and last time of the whole record.

    ``init`` needs the columns' names and the time range only: of a text file it reads
    :data:`SAMPLE_ROWS` rows in full (names, derived channels checked) and then the time
    column alone (checked as ``identify`` checks it), so that a file of millions of rows
    is never held whole. Other formats are read whole.
    """
    if data.suffix.lower() not in (".csv", ".tsv", ".txt", ""):
        probe = load_data(data, time_column=time, derived=derived)
        return probe, float(probe.time[0]), float(probe.time[-1])
    probe = load_data(data, time_column=time, derived=derived, read_options={"nrows": SAMPLE_ROWS})
    if len(probe) < SAMPLE_ROWS:
        return probe, float(probe.time[0]), float(probe.time[-1])
    whole = load_data(
        data, time_column=time, read_options={"usecols": lambda c: str(c).strip(" ") == time}
    )
    return probe, float(whole.time[0]), float(whole.time[-1])


def _time_column(data: Path) -> str:
    """Return the column named ``time`` (any case), else the first column of a text file."""
    if data.suffix.lower() not in (".csv", ".tsv", ".txt", ""):
        return "time"
    import pandas as pd

    try:
        cols = [str(c) for c in pd.read_csv(data, nrows=0, sep=None, engine="python").columns]
    except (OSError, ValueError) as exc:
        raise StudyError(f"{data}: cannot read the column names ({type(exc).__name__})") from None
    if not cols:
        raise StudyError(f"{data}: no columns")
    return next((c for c in cols if c.strip().lower() == "time"), cols[0])
