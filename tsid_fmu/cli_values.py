"""The values of ``tsid``'s options, checked as the shell expects.

A bad value stops ``tsid`` at argument parsing, before a study or FMU is read, with
one line naming the option (argparse's exit status 2); values that need the study
(``--set`` names, ``--result``) are :class:`~tsid_fmu.errors.StudyError` naming the
option and the file or name, with the close matches where a name is misspelt.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tsid_fmu.errors import StudyError

__all__ = [
    "choice_value",
    "iteration_count",
    "not_parameters",
    "parse_assignments",
    "saved_result",
    "timeout_seconds",
    "whole_at_least",
    "worker_count",
]


def whole_at_least(text: str, low: int, what: str = "", note: str = "") -> int:
    """Return ``text`` as a whole number of at least ``low``; ArgumentTypeError otherwise.

    ``what`` follows "a whole number" and ``note`` follows "at least N" in the message.
    """
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number{what}, got {text!r}") from None
    if n < low:
        raise argparse.ArgumentTypeError(f"must be at least {low}{note}, got {text!r}")
    return n


def worker_count(text: str) -> int:
    """Return the value of ``--workers``: a whole number of processes, at least 1.

    Raises
    ------
    argparse.ArgumentTypeError
        Anything else (argparse names the option and exits with status 2).
    """
    return whole_at_least(text, 1, " of worker processes (1 = serial)", " (1 = serial)")


def iteration_count(text: str) -> int:
    """Return the value of ``--max-iterations``, ``--pause-after`` or ``--continue-from-run``.

    A whole number, at least 1 (runs and iterations count from 1, as the trail does).

    Raises
    ------
    argparse.ArgumentTypeError
        Anything else (argparse names the option and exits with status 2).
    """
    return whole_at_least(text, 1)


def timeout_seconds(text: str) -> float:
    """Return the value of ``--timeout``: seconds per simulation, or 0 for no limit.

    Raises
    ------
    argparse.ArgumentTypeError
        A negative, non-finite or non-numeric value (argparse names the option and
        exits with status 2).
    """
    try:
        seconds = float(text)
    except ValueError:
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds >= 0):
        raise argparse.ArgumentTypeError(
            "must be a number of seconds > 0, or 0 for no limit (leave it out for the "
            f"automatic limit), got {text!r}"
        )
    return seconds


def choice_value(choice: Any, name: str, text: str) -> float:
    """Return the number ``--set NAME=TEXT`` sets a choice to: by label or by value.

    ``model=Drag`` names an FMU variant, ``friction=coulomb`` an Enumeration item,
    ``friction=2`` a value; anything that is not one of the study's choices is refused.

    Raises
    ------
    StudyError
        ``text`` is none of the choices, naming them.
    """
    labels = [str(x) for x in choice.labels]
    if text in labels:
        return float(choice.values[labels.index(text)])
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if value in choice.values:
        return value
    raise StudyError(
        f"--set {name}={text}: not one of the study's choices for {name} ({', '.join(labels)})"
    )


def parse_assignments(items: Sequence[str], what: str, last: bool = False) -> dict[str, str]:
    r"""Return ``{NAME: VALUE}`` of options such as ``--set NAME=VALUE``.

    Parameters
    ----------
    items : sequence of str
        The options' texts.
    what : str
        The option, named in an error (``--set``).
    last : bool, optional
        Split at the last ``=``, for values that cannot hold one (``--set``'s numbers and
        labels): a name may then hold ``=`` (``--set a=b=5`` sets ``a=b``). A name
        written as a TOML basic string (``--set '" x "=5'``) is taken as it is, spaces
        at its ends and escapes (``\"``, ``\u0041``) included; others are stripped.

    Raises
    ------
    StudyError
        An item is not ``NAME=VALUE``, naming the option ``what``.
    """
    out = {}
    for item in items:
        name, sep, value = item.rpartition("=") if last else item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise StudyError(f"{what} must look like NAME=VALUE, got {item!r}")
        out[_quoted_name(name, what, item) if last else name.strip()] = value.strip()
    return out


def _quoted_name(name: str, what: str, item: str) -> str:
    """``name`` stripped, or the text of a TOML basic string ``"..."``."""
    import tomllib

    text = name.strip()
    if not (len(text) >= 2 and text[0] == text[-1] == '"'):
        return text
    try:
        if not re.fullmatch(r'"(?:[^"\\\x00-\x1f\x7f]|\\.)*"', text):
            raise tomllib.TOMLDecodeError("not one basic string")
        value = tomllib.loads(f"name = {text}")["name"]
    except tomllib.TOMLDecodeError:
        raise StudyError(
            f'{what} {item!r}: a quoted name must be a TOML basic string (\\" for a quote)'
        ) from None
    if not value:
        raise StudyError(f"{what} must look like NAME=VALUE, got {item!r}")
    return value


def saved_result(path: Path) -> dict[str, Any]:
    """Return result.json of ``--result`` (a results folder or the file), checked.

    Raises
    ------
    StudyError
        No such file or folder, a folder without result.json, or no parameters in it.
    """
    import json

    if not path.exists():
        raise StudyError(f"--result {path}: no such file or folder")
    file = path / "result.json" if path.is_dir() else path
    if not file.is_file():
        raise StudyError(
            f"--result {path}: no result.json in this folder (is it the --out folder of a "
            "finished tsid identify?)"
        )
    try:
        saved = json.loads(file.read_text(encoding="utf-8"))
        values = saved.get("params", saved.get("x"))  # "x" by name: tsid-fmu 0.2
        if not isinstance(values, dict):
            raise TypeError("no parameters")
        saved["params"] = {str(k): float(v) for k, v in values.items()}
    except (OSError, UnicodeDecodeError, ValueError, TypeError, AttributeError) as exc:
        raise StudyError(
            f"{file}: cannot read identified parameters ({type(exc).__name__})"
        ) from None
    return saved


def not_parameters(unknown: Sequence[str], names: Sequence[str]) -> str:
    """Return the message for ``--set`` names that are no parameter, with close ones."""
    import difflib

    said = []
    for n in unknown:
        close = difflib.get_close_matches(n, names, n=3, cutoff=0.6)
        hint = f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
        said.append(f"{n!r}{hint}")
    return f"--set: not a parameter of the study: {', '.join(said)}; its parameters: " + ", ".join(
        names
    )
