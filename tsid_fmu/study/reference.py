"""The study-file reference page, generated from the loader and the parts' docstrings.

Every key that :mod:`tsid_fmu.study.toml` accepts is listed with its type, its default
and its meaning. The keys come from the loader's own sets, the defaults from the
dataclass fields the keys fill, the meanings from those dataclasses' numpydoc
``Parameters`` and ``Attributes`` sections. A key without such text is reported as
undocumented, never described from elsewhere. ``python -m tsid_fmu.study.reference``
prints the page (committed as ``docs/reference/study-file.md``).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import re
import sys
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.study.choice import Choice, ModelChoice
from tsid_fmu.study.definition import Study
from tsid_fmu.study.designopts import DesignOptions
from tsid_fmu.study.schema import ContributionOptions, Experiment, Method, Parameter, Phase
from tsid_fmu.study.toml import (
    _CONTRIB_TYPES,
    _DATA,
    _DESIGN_TYPES,
    _LEVELING_TYPES,
    _METHOD_TYPES,
    _PARAM,
    _PHASE,
    _STUDY,
    _TOP,
    _TYPE_NAMES,
)

__all__ = ["COMMAND", "PAGE", "TABLES", "UNDOCUMENTED", "Row", "Table", "render", "rows"]

COMMAND = "python -m tsid_fmu.study.reference"
"""The command that prints the page."""

PAGE = "docs/reference/study-file.md"
"""Where the page is committed, relative to the repository root."""

UNDOCUMENTED = "**undocumented**"
"""The meaning written for a key whose field has no docstring text."""


@dataclass(frozen=True)
class Table:
    """One table of a study file and the dataclasses whose fields its keys fill.

    Attributes
    ----------
    names : tuple of str
        The loader's top-level keys (``_TOP``) that this table covers.
    heading : str
        How the table is written in a file (``[method]``, ``[[phases]]``).
    keys : collection of str
        The keys the loader accepts in the table (its own set or dict of types).
    owners : tuple of type
        The dataclasses whose fields the keys fill, searched in this order.
    renames : dict of str to (type, str)
        TOML key -> (dataclass, field) for a key that is not a field of the owners.
    kinds : dict of str to type
        The type the loader checks for each key, where it keeps one per key.
    need : str
        Whether the table must be given.
    form : str
        How the table is written, where it is more than ``key = value`` lines.
    """

    names: tuple[str, ...]
    heading: str
    keys: Collection[str]
    owners: tuple[type, ...]
    renames: dict[str, tuple[type, str]] = field(default_factory=dict)
    kinds: dict[str, type] = field(default_factory=dict)
    need: str = "optional"
    form: str = ""


TABLES = (
    Table(
        ("study",), "[study]", _STUDY, (Study,), need="required, unless a parameter gives `fmus`"
    ),
    Table(
        ("data", "experiments"),
        "[data] or [[experiments]]",
        _DATA,
        (Experiment,),
        {"file": (Experiment, "data"), "time": (Experiment, "time_column")},
        need="required: one of the two",
        form="`[data]` for one experiment, or one `[[experiments]]` table per experiment "
        "(not both).",
    ),
    Table(
        ("parameters",),
        "[parameters]",
        _PARAM,
        (Parameter,),
        {"choices": (Choice, "choices"), "fmus": (ModelChoice, "choices")},
        need="required",
        form="One entry per parameter, `NAME = { levels = [1, 2, 3], min = 0 }`; a "
        "discrete factor gives `choices` only, a choice among FMU files `fmus` only. "
        '`"delay(<input>)" = { levels = [0, 0.5e-3, 1e-3] }` identifies a delay of that '
        "input in seconds (docs/how-to/input-delay.md).",
    ),
    Table(("method",), "[method]", _METHOD_TYPES, (Method,), kinds=_METHOD_TYPES),
    Table(("leveling",), "[leveling]", _LEVELING_TYPES, (LevelingOptions,), kinds=_LEVELING_TYPES),
    Table(("phases",), "[[phases]]", _PHASE, (Phase,), form="One table per phase."),
    Table(
        ("contribution",),
        "[contribution]",
        _CONTRIB_TYPES,
        (ContributionOptions,),
        kinds=_CONTRIB_TYPES,
    ),
    Table(
        ("design",),
        "[design]",
        _DESIGN_TYPES,
        (DesignOptions,),
        kinds=_DESIGN_TYPES,
        form="Read by `tsid design` only: the experiments it may propose.",
    ),
)
"""The tables of a study file, in the page's order."""

_PATH = "a string (a file path, relative to the study file)"
_TYPES = {
    ("study", "fmu"): _PATH,
    ("data", "file"): _PATH,
    ("parameters", "choices"): "a list of integers, of true/false or of strings",
    ("parameters", "fmus"): "a list of strings (FMU files, relative to the study file)",
}
# where the loader (toml.py) fills a value the dataclass has no default for, or its own
_DEFAULTS = {
    ("study", "fmu"): "required (unless a parameter gives `fmus`)",
    ("study", "name"): "the FMU file's name without `.fmu` (with `fmus`: the study file's)",
    ("data", "name"): "the data file's name without its extension",
    ("data", "outputs"): "required",
    ("parameters", "levels"): "required for a Real parameter",
    ("parameters", "choices"): "required for a discrete factor",
    ("parameters", "fmus"): "required for a choice among FMU files",
    ("contribution", "enabled"): "`true` where the table is given, else `false`",
}
# the loader's names of its types (str, float, ...), then those of the fields' other types
_ANNOTATIONS = {kind.__name__: text for kind, text in _TYPE_NAMES.items()} | {
    "Path": _PATH,
    "dict[str, str]": "a table of strings",
    "dict[str, float]": "a table of numbers",
    "dict[str, list[float]]": "a table of lists of numbers",
    "list[str]": "a list of strings",
    "list[float]": "a list of numbers",
    "list[list[float]]": "a list of [start, end] pairs of numbers",
    "float | list[float]": "a number or a list of numbers",
}


@dataclass(frozen=True)
class Row:
    """One key of one table, as the page lists it.

    Attributes
    ----------
    table : str
        The table's heading.
    key : str
        The TOML key.
    type : str
        What the key takes, in words.
    default : str
        The value when the key is left out, or ``required``.
    meaning : str
        The first paragraph of the field's docstring text, or :data:`UNDOCUMENTED`.
    python : str
        ``Class.field`` where the field is not the key of the table's own class.
    """

    table: str
    key: str
    type: str
    default: str
    meaning: str
    python: str


def _markdown(text: str) -> str:
    """Return reStructuredText markup as Markdown on one line, pipes escaped."""
    text = re.sub(r"(?::\w+)?:\w+:`~?([^`]+)`", r"`\1`", text)
    text = text.replace("``", "`")
    return " ".join(text.split()).replace("|", "\\|")


def _section_entries(lines: list[str], start: int) -> dict[str, tuple[str, str]]:
    """Return name -> (type, first paragraph) of a numpydoc section starting at ``start``."""
    entries: dict[str, tuple[str, str]] = {}
    names: list[str] = []
    spec, para, done = "", [], False
    for i in range(start, len(lines) + 1):
        line = lines[i] if i < len(lines) else ""
        ends = i == len(lines) or (i + 1 < len(lines) and set(lines[i + 1]) == {"-"})
        if ends or (line and not line[0].isspace()):
            for name in names:
                entries[name] = (spec, _markdown(" ".join(para)))
            if ends:
                return entries
            head, _, spec = line.partition(" : ")
            names = [n.strip() for n in head.split(",")]
            para, done = [], False
        elif not line.strip():
            done = done or bool(para)
        elif not done:
            para.append(line.strip())
    return entries


def doc_entries(cls: type) -> dict[str, tuple[str, str]]:
    """Return name -> (type, meaning) from the numpydoc fields of a class's own docstring.

    Parameters
    ----------
    cls : type
        A dataclass; its ``Parameters`` and ``Attributes`` sections are read (a base
        class's docstring is not).

    Returns
    -------
    dict of str to (str, str)
        Each documented name's type text and the first paragraph of its description,
        as Markdown on one line (empty where an entry has no text).
    """
    lines = inspect.cleandoc(cls.__dict__.get("__doc__") or "").splitlines()
    found: dict[str, tuple[str, str]] = {}
    for i, line in enumerate(lines[:-1]):
        if line.strip() in ("Parameters", "Attributes") and set(lines[i + 1]) == {"-"}:
            found.update(_section_entries(lines, i + 2))
    return found


def _owner(table: Table, key: str) -> tuple[type, str] | None:
    """Return the dataclass and field that ``key`` fills, or None."""
    if key in table.renames:
        return table.renames[key]
    for cls in table.owners:
        if key in {f.name for f in dataclasses.fields(cls)}:
            return cls, key
    return None


def _field(cls: type, name: str) -> dataclasses.Field:
    """Return the dataclass field ``name`` of ``cls``."""
    return next(f for f in dataclasses.fields(cls) if f.name == name)


def _literal(value: Any) -> str:
    """Return a default as a study file writes it (``unset`` for None)."""
    if value is None:
        return "unset"
    if isinstance(value, float) and math.isinf(value):
        return "`-inf`" if value < 0 else "`inf`"
    return f"`{json.dumps(value)}`"


def _default(table: Table, key: str, cls: type, name: str) -> str:
    """Return the default of ``key``: the loader's, else the dataclass field's."""
    special = _DEFAULTS.get((table.names[0], key))
    if special is not None:
        return special
    spec = _field(cls, name)
    if spec.default is not dataclasses.MISSING:
        return _literal(spec.default)
    if spec.default_factory is not dataclasses.MISSING:
        return _literal(spec.default_factory())
    return "required"


def _type(table: Table, key: str, cls: type, name: str, spec: str) -> str:
    """Return what ``key`` takes, in words, with the choices its docstring lists."""
    kind = table.kinds.get(key)
    annotation = str(_field(cls, name).type).removesuffix(" | None")
    if (table.names[0], key) in _TYPES:
        text = _TYPES[(table.names[0], key)]
    elif kind is not None and kind not in (dict, list):
        text = _TYPE_NAMES[kind]
    else:
        text = _ANNOTATIONS.get(annotation, annotation or "unknown")
    choices = re.match(r"\{([^}]*)\}", spec)
    if choices:
        text += ": one of " + ", ".join(f"`{c.strip()}`" for c in choices.group(1).split(","))
    return text


def _order(table: Table, key: str) -> tuple[int, int, str]:
    """Return where ``key`` sorts: its owner's position, then its field's."""
    found = _owner(table, key)
    classes = [*table.owners, *(c for c, _ in table.renames.values())]
    if found is None:
        return (len(classes), 0, key)
    names = [f.name for f in dataclasses.fields(found[0])]
    return (classes.index(found[0]), names.index(found[1]), key)


def _row(table: Table, key: str) -> Row:
    """Return the page's row of one key."""
    found = _owner(table, key)
    if found is None:  # a key the loader accepts but no dataclass field holds
        return Row(table.heading, key, "unknown", "unknown", UNDOCUMENTED, "")
    cls, name = found
    spec, meaning = doc_entries(cls).get(name, ("", ""))
    python = "" if (cls, name) == (table.owners[0], key) else f"{cls.__name__}.{name}"
    return Row(
        table=table.heading,
        key=key,
        type=_type(table, key, cls, name, spec),
        default=_default(table, key, cls, name),
        meaning=meaning or UNDOCUMENTED,
        python=python,
    )


def rows() -> list[Row]:
    """Return a row for every key of every table the loader accepts, in page order."""
    return [
        _row(table, key)
        for table in TABLES
        for key in sorted(table.keys, key=lambda k, t=table: _order(t, k))
    ]


def undocumented(found: list[Row] | None = None) -> list[str]:
    """Return ``"<table> <key>"`` for every key without docstring text, and stray tables.

    Parameters
    ----------
    found : list of Row, optional
        The rows to check; default :func:`rows`.
    """
    found = rows() if found is None else found
    missing = [f"{r.table} {r.key}" for r in found if r.meaning == UNDOCUMENTED]
    covered = {name for table in TABLES for name in table.names}
    return missing + [f"[{name}] (no section)" for name in sorted(_TOP - covered)]


def _code(heading: str) -> str:
    """Return a table's heading as code (``[data]`` or ``[[experiments]]`` each apart)."""
    return " or ".join(f"`{part}`" for part in heading.split(" or "))


def _summary(cls: type) -> str:
    """Return the first line of a class's docstring, as Markdown."""
    return _markdown(inspect.cleandoc(cls.__dict__.get("__doc__") or "").partition("\n")[0])


def _header() -> list[str]:
    """Return the page's title, its introduction and the list of tables."""
    lines = [
        "# Study file reference",
        "",
        "A study file is a TOML file that describes one identification: the FMU, the "
        "measured experiments and how their data columns map to the FMU's inputs and "
        "outputs, the parameters to identify with their first levels, and how to identify "
        "them (the cost, the orthogonal arrays, the re-leveling rules, phases). "
        "`tsid_fmu.study.toml` reads it (`Study.from_toml`); a key not listed here, a value "
        "of the wrong type or out of range is an error that names the file and the key. "
        "File paths are relative to the study file's folder. Examples: "
        "`examples/lsea_siso/study.toml`, `examples/lsea_miso/study.toml`.",
        "",
        f"This page is generated by `{COMMAND}` from the loader's own sets of keys and the "
        "numpydoc docstrings of the dataclasses the keys fill; do not edit it by hand.",
        "",
        "| Table | Given | Python classes | What it holds |",
        "| --- | --- | --- | --- |",
    ]
    for table in TABLES:
        classes = dict.fromkeys([*table.owners, *(c for c, _ in table.renames.values())])
        names = ", ".join(f"`{c.__module__}.{c.__name__}`" for c in classes)
        summary = _summary(table.owners[0])
        lines.append(f"| {_code(table.heading)} | {table.need} | {names} | {summary} |")
    lines.append("")
    return lines


def render() -> str:
    """Return the reference page as Markdown."""
    lines = _header()
    found = rows()
    for table in TABLES:
        cls = table.owners[0]
        lines += [
            f"## {_code(table.heading)}",
            "",
            f"{_summary(cls)} Keys fill the fields of `{cls.__module__}.{cls.__name__}`"
            + ("; the Python name is given where it differs." if table.renames else ".")
            + (f" {table.form}" if table.form else ""),
            "",
            "| Key | Type | Default | Meaning | Python name |",
            "| --- | --- | --- | --- | --- |",
        ]
        for r in (r for r in found if r.table == table.heading):
            python = f"`{r.python}`" if r.python else ""
            lines.append(f"| `{r.key}` | {r.type} | {r.default} | {r.meaning} | {python} |")
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    """Print the page; exit status 1 (and the keys on stderr) where a key is undocumented."""
    sys.stdout.write(render())
    missing = undocumented()
    for label in missing:
        print(f"undocumented study-file key: {label}", file=sys.stderr)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
