"""Who owns an output folder: the fingerprint of its study, and a lock while it runs.

A study folder holds ``fingerprint.json``: the normalised study (every setting under a
dotted key such as ``method.seed`` or ``parameters.tau.levels``), the FMU's GUID and
SHA-256 and each data file's SHA-256, with a digest of the whole. Before a study writes
anything into ``--out`` it compares:

* a folder holding files but no fingerprint holds files tsid-fmu did not write
  (or a trail of a version that kept none): refused;
* a fingerprint of another study (any key differs) with results in the folder:
  refused, naming the keys that differ, with or without ``--resume``; a folder that
  a study left before finishing anything (only the fingerprint and ``study.toml``)
  may be taken over;
* the same study: ``--resume`` continues it; without it the folder is refused once it
  holds results.

While a study runs it holds an advisory lock (``fcntl.flock``) on ``.tsid.lock`` in
the folder, so a second process on the same folder stops with a message naming it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from tsid_fmu.errors import StudyError
from tsid_fmu.study.definition import Study
from tsid_fmu.trail.files import read_json, strict, write_json
from tsid_fmu.trail.integrity import seal, sha256_file, unseal

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no advisory lock
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "FINGERPRINT",
    "LOCK",
    "FolderLock",
    "check_owner",
    "differences",
    "fingerprint",
    "read_fingerprint",
    "write_fingerprint",
]

FINGERPRINT = "fingerprint.json"
LOCK = ".tsid.lock"
_BOOKKEEPING = frozenset({FINGERPRINT, LOCK, "study.toml"})
_RESULTS = ("record.json", "stage.json", "result.json")
_MISSING = "missing"


def _plain(value: Any) -> Any:
    """``value`` as JSON data, with non-finite floats as ``'inf'``, ``'nan'``."""
    return strict(value, nonfinite=repr)


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    """Store ``value`` under dotted keys (an empty table stores nothing)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def _file_hash(path: Path) -> str:
    try:
        return sha256_file(path)
    except OSError:
        return _MISSING


def _fmu_guid(path: Path) -> str | None:
    """Return the GUID (FMI 2) or instantiation token (FMI 3) of an FMU, or None."""
    try:
        with zipfile.ZipFile(path) as archive, archive.open("modelDescription.xml") as fh:
            for _, element in ElementTree.iterparse(fh, events=("start",)):
                return element.get("guid") or element.get("instantiationToken")
    except (OSError, KeyError, ValueError, EOFError, RuntimeError, NotImplementedError,
            zipfile.BadZipFile, ElementTree.ParseError):  # fmt: skip
        return None
    return None


def _data_hash(data: Any) -> str:
    if isinstance(data, str | os.PathLike):
        return _file_hash(Path(data))
    try:
        import pandas as pd

        rows = pd.util.hash_pandas_object(data, index=True).to_numpy().tobytes()
        head = json.dumps([str(c) for c in data.columns]).encode()
    except (TypeError, ValueError, AttributeError):
        return _MISSING
    return hashlib.sha256(head + rows).hexdigest()


def fingerprint(study: Study) -> dict[str, Any]:
    """Return the normalised study as ``{dotted key: value}`` (see the module doc)."""
    items: dict[str, Any] = {
        "name": study.name,
        "interface": study.interface,
        "step_size": _plain(study.step_size),
        "fmu.guid": _fmu_guid(study.fmu),
        "fmu.sha256": _file_hash(study.fmu),
        "parameters": [p.name for p in study.parameters],
        "experiments": [e.name for e in study.experiments],
    }
    _flatten("start_values", _plain(study.start_values), items)
    _flatten("method", _plain(study.method), items)
    for p in study.parameters:
        _flatten(f"parameters.{p.name}", {k: v for k, v in _plain(p).items() if k != "name"}, items)
    for e in study.experiments:
        fields = {
            f.name: _plain(getattr(e, f.name))
            for f in dataclasses.fields(e)
            if f.name not in ("data", "name")
        }
        fields["data.sha256"] = _data_hash(e.data)
        _flatten(f"experiments.{e.name}", fields, items)
    _flatten("phases", {str(i + 1): _plain(ph) for i, ph in enumerate(study.phases)}, items)
    _flatten("contribution", _plain(study.contribution), items)
    if study.choices:  # only where there are some: older folders keep their fingerprint
        items["choices"] = {c.name: [str(v) for v in c.choices] for c in study.choices}
    if study.variants is not None:  # a choice among FMU files: each file's contents
        for path in study.variants.paths:
            items[f"variants.{path.name}.sha256"] = _file_hash(path)
    return items


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 40 else text[:37] + "..."


def differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """Return ``"key: old -> new"`` for every key that differs."""
    out = []
    for key in sorted(set(old) | set(new)):
        if key not in new:
            out.append(f"{key} (removed)")
        elif key not in old:
            out.append(f"{key} (added)")
        elif old[key] != new[key]:
            out.append(f"{key}: {_short(old[key])} -> {_short(new[key])}")
    return out


def write_fingerprint(out: Path, items: dict[str, Any]) -> None:
    """Write ``fingerprint.json`` (with its digest)."""
    write_json(out / FINGERPRINT, seal({"format": 1, "tool": "tsid-fmu", "study": items}))


def read_fingerprint(path: Path) -> dict[str, Any]:
    """Return the study items of a ``fingerprint.json``, after checking its digest."""
    advice = "tsid-fmu cannot tell which study the folder holds; choose another --out folder"
    body = unseal(read_json(path, "study fingerprint"), path, "study fingerprint", advice)
    if not isinstance(body.get("study"), dict):
        raise StudyError(f"{path}: damaged study fingerprint (no study)")
    return body["study"]


def _foreign(out: Path, owned: bool) -> list[str]:
    """Names in ``out`` that tsid-fmu's bookkeeping does not explain."""
    ours = _BOOKKEEPING if owned else _BOOKKEEPING - {"study.toml"}
    names = []
    for p in sorted(out.iterdir()):
        temporary = p.name.startswith(".") and p.name.endswith(".tmp")
        if p.name not in ours and not temporary:
            names.append(p.name + ("/" if p.is_dir() else ""))
    return names


def check_owner(out: Path, items: dict[str, Any], resume: bool, locked: bool) -> bool:
    """Check that ``out`` may hold this study; return True if it is new to it.

    Before the lock is taken (``locked=False``) only what refuses a folder whatever
    runs in it is checked, and nothing is written: a folder that is refused stays as
    it was. Under the lock the state of this study's trail is checked too.

    Raises
    ------
    StudyError
        ``out`` holds files tsid-fmu did not write, another study with results, or
        (without ``resume``) this study's results; or ``resume`` finds nothing.
    """
    if out.exists() and not out.is_dir():
        raise StudyError(f"{out}: not a folder; choose another --out")
    owned = (out / FINGERPRINT).is_file()
    foreign = _foreign(out, owned) if out.is_dir() else []
    if not owned:
        if foreign:
            shown = ", ".join(repr(n) for n in foreign[:5]) + (", ..." if len(foreign) > 5 else "")
            raise StudyError(
                f"{out} holds files tsid-fmu did not write ({shown}), or a study without a "
                "fingerprint; choose an empty or new --out folder"
            )
        if resume:
            raise StudyError(f"{out}: nothing to resume (no study in this folder)")
        return True
    changed = differences(read_fingerprint(out / FINGERPRINT), items)
    if changed and (foreign or resume):
        head = (
            f"--resume: the study changed since {out} was written"
            if resume
            else f"{out} holds another study"
        )
        more = f" (and {len(changed) - 8} more)" if len(changed) > 8 else ""
        raise StudyError(
            f"{head}; keys that differ: {'; '.join(changed[:8])}{more}; choose another "
            "--out folder, or undo the change"
        )
    if changed:
        return True  # a study that stopped before it wrote anything: taken over
    if locked and not resume and any(next(out.rglob(m), None) for m in _RESULTS):
        raise StudyError(
            f"{out} already holds this study; continue it with --resume, or choose "
            "another --out folder"
        )
    return False


class FolderLock:
    """An advisory lock on ``.tsid.lock`` in a study folder, held while a study runs."""

    def __init__(self, out: Path) -> None:
        self.path = out / LOCK
        self._fh: Any = None

    def acquire(self) -> None:
        """Take the lock, or raise StudyError naming the lock and its holder."""
        if fcntl is None:  # pragma: no cover - Windows
            return
        fh = open(self.path, "a+", encoding="utf-8")  # held until release()
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            holder = fh.read(32).strip()
            fh.close()
            who = f"process {holder}" if holder.isdigit() else "another process"
            raise StudyError(
                f"{self.path.parent} is in use: {who} holds its lock {self.path}; wait for "
                "it to finish, or choose another --out folder"
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"{os.getpid()}\n")
        fh.flush()
        self._fh = fh

    def release(self) -> None:
        """Give the lock back (the lock file stays)."""
        if self._fh is not None:
            fcntl.flock(self._fh.fileno(), fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None
