"""README's "Using it" and "Reports" snippets are taken from files and commands that run.

* every command of the bash block parses with ``tsid``'s own parser (placeholders
  ``STUDY.toml`` and ``DIR`` stand for the SISO example and a temporary folder), and
  those that name only shipped files run, in a temporary folder;
* the Python block runs as written (slow: one SISO study);
* every line of the TOML block is a line of ``examples/lsea_siso/study.toml``, in order
  (that study is run by ``tests/test_examples.py``).
"""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import pytest

from tsid_fmu.cli import main, make_parser

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text(encoding="utf-8")


def _section(title: str) -> str:
    start = README.index(f"## {title}\n")
    end = README.find("\n## ", start + 1)
    return README[start : end if end > 0 else None]


def _blocks(lang: str) -> list[str]:
    text = _section("Using it") + _section("Reports")
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _commands() -> list[list[str]]:
    (block,) = _blocks("bash")
    out = []
    for line in block.splitlines():
        command = line.split("  #")[0].strip()
        if command:
            out.append(shlex.split(command))
    return out


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    for name in ("examples", "fmus", "models"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _fill(argv: list[str]) -> list[str]:
    mapping = {"STUDY.toml": "examples/lsea_siso/study.toml", "DIR": "out"}
    return [mapping.get(a, a) for a in argv]


def test_every_command_parses():
    commands = _commands()
    assert len(commands) >= 10
    parser = make_parser()
    for argv in commands:
        assert argv[0] == "tsid", argv
        if argv[1:] == ["--version"]:
            continue
        parser.parse_args(_fill(argv[1:]))


def test_commands_on_shipped_files_run(workdir, capsys):
    ran = 0
    for argv in _commands():
        if any(a in ("STUDY.toml", "DIR") for a in argv) and argv[1] != "simulate":
            continue
        if argv[1] == "simulate" and "--result" in argv:
            continue
        if argv[1:] == ["--version"]:
            with pytest.raises(SystemExit) as stop:
                main(argv[1:])
            assert stop.value.code == 0
        else:
            assert main(_fill(argv[1:])) == 0, argv
        ran += 1
    assert ran >= 5
    assert (workdir / "study.toml").is_file()  # tsid init
    assert "LSEA_SISO" in capsys.readouterr().out


def test_toml_snippet_is_taken_from_the_siso_study():
    (block,) = _blocks("toml")
    source = (REPO / "examples" / "lsea_siso" / "study.toml").read_text().splitlines()
    position = 0
    for line in block.splitlines():
        if not line.strip():
            continue
        assert line in source[position:], f"README line not in the SISO study: {line!r}"
        position = source.index(line, position) + 1


@pytest.mark.slow
def test_python_snippet_runs(workdir):
    (block,) = _blocks("python")
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    res = namespace["res"]
    assert res.success and (workdir / "results" / "siso" / "report.html").is_file()
    assert len(namespace["figures"]) == 4
    assert os.path.basename(str(res.study.fmu)) == "LSEA_SISO.fmu"


def test_every_path_the_readme_names_is_in_the_repository():
    # issue 26: it cited ../shared/seeds/, which a user of the package does not have
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert not re.findall(r"`\.\./[^`]*`|\]\(\.\./", text)
    for path in re.findall(
        r"`((?:examples|fmus|models|benchmarks|docs|tests|tsid_fmu)/[^`\s]*)`", text
    ):
        clean = path.split("::")[0].rstrip(".,:;)")
        if "*" in clean or "{" in clean or "NN" in clean:
            continue
        assert (REPO / clean).exists(), path
