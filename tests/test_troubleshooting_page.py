"""What ``docs/how-to/troubleshooting.md`` tells users holds (issue 64, "docs true by
construction").

* every study-file key the page tells users to set (a backticked ``key = value``) is a
  key the study file accepts, in the table the page names where it names one
  (``in `[method]```); the keys come from the loader's own sets
  (:func:`tsid_fmu.study.reference.rows`), so a key the loader refuses, such as
  ``read_options`` or ``decimal``, fails;
* the messages the page quotes for a study pointed at ``/etc/passwd`` are what ``tsid``
  prints: exactly, for a passwd file without commas; for the machine's own
  ``/etc/passwd`` (where there is one) with its line and field counts left open, as they
  differ from one machine to another.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fmu_factory import lag_case

from tsid_fmu.cli import main
from tsid_fmu.study.reference import rows

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "how-to" / "troubleshooting.md"
TEXT = PAGE.read_text(encoding="utf-8")

# a TOML value as the page writes one, "..." standing for what the user fills in
VALUE = r'(?:"[^"`]*"|\{[^`]*\}|\[[^`]*\]|true|false|[-+]?\d[\d.e+-]*|\.\.\.)'
SNIPPET = re.compile(rf"`([A-Za-z_][A-Za-z_0-9]*) = ({VALUE})`(?: (?:in|to) `(\[[^`]+\])`)?")


def _snippets() -> list[tuple[str, str, str | None]]:
    """Every ``key = value`` the page shows, with the table it names after it (or None)."""
    return [(m[1], m[2], m[3]) for m in SNIPPET.finditer(TEXT)]


def _keys() -> dict[str, set[str]]:
    """Every key the study file accepts -> the tables that accept it."""
    out: dict[str, set[str]] = {}
    for row in rows():
        out.setdefault(row.key, set()).update(t.strip() for t in row.table.split(" or "))
    return out


def test_the_page_shows_study_keys_to_set():
    """The parser finds the page's snippets: a change of their form fails here, not silently."""
    found = {key for key, _, _ in _snippets()}
    assert {"fidelity", "interface", "time", "cost", "refine", "step"} <= found, found


def test_every_key_the_page_tells_users_to_set_is_a_study_key():
    keys = _keys()
    wrong = []
    for key, value, table in _snippets():
        if value.startswith("{") and "levels" in value:  # a [parameters] entry: NAME = {...}
            inner = re.findall(r"([A-Za-z_]\w*) =", value)
            wrong += [f"{key}: {k}" for k in inner if "[parameters]" not in keys.get(k, set())]
            continue
        if key not in keys:
            wrong.append(f"{key} = {value}: not a study-file key")
        elif table is not None and table not in keys[key]:
            wrong.append(f"{key} in {table}: accepted only in {sorted(keys[key])}")
    assert wrong == [], wrong


def test_the_refused_reader_options_are_not_offered():
    """``read_options`` is a ``load_data`` argument in Python, not a study-file key."""
    assert "read_options" not in _keys()
    assert "read_options" not in TEXT


PASSWD_LIKE = (
    "root:x:0:0:root:/root:/bin/bash\n"
    "daemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\n"
    "alice:x:1000:1000:Alice Secretname:/home/alice:/bin/zsh\n"
)


def _quoted() -> tuple[str, str]:
    """The two messages the page quotes for a study pointed at ``/etc/passwd``."""
    text = " ".join(TEXT.split())
    para = text[text.index("(say `/etc/passwd`)") :]
    para = para[: para.index("## ")]
    system = re.search(r"`tsid` prints `(tsid: error: /etc/passwd: [^`]+)`", para)
    commaless = re.search(r"without commas gives `([^`]+)`", para)
    assert system and commaless, para
    return system[1], commaless[1]


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return lag_case(tmp_path_factory.mktemp("lag"), 0.01)


def _tsid_error(tmp_path: Path, fmu: Path, data: str, capsys) -> str:
    study = tmp_path / "study.toml"
    study.write_text(
        f'[study]\nfmu = "{fmu.as_posix()}"\n[data]\nfile = "{data}"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\n[method]\nmax_iterations = 1\n'
        "[parameters]\ntau = { levels = [0.1, 0.3, 0.6], min = 0 }\n"
    )
    rc = main(["identify", str(study), "--out", str(tmp_path / "out"), "-q", "--no-plots"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    return err.rstrip("\n")


def test_the_wrong_file_messages_are_what_tsid_prints(lag, tmp_path, capsys):
    system, commaless = _quoted()
    path = tmp_path / "passwd"
    path.write_text(PASSWD_LIKE)
    assert _tsid_error(tmp_path, lag, path.as_posix(), capsys) == (
        f"tsid: error: {path.as_posix()}: {commaless}"
    )
    if Path("/etc/passwd").is_file():
        got = _tsid_error(tmp_path, lag, "/etc/passwd", capsys)
        if "," in Path("/etc/passwd").read_text(encoding="utf-8", errors="replace"):
            pattern = re.sub(r"\d+", r"\\d+", re.escape(system))
            assert re.fullmatch(pattern, got), (got, system)
        else:  # no commas: one column, the other message
            assert got.endswith(commaless), got
