"""The snippets of the README and the docs are taken from files and commands that run.

* every command of the bash block of ``docs/reference/cli.md`` parses with ``tsid``'s own
  parser (placeholders ``STUDY.toml`` and ``DIR`` stand for the SISO example and a
  temporary folder), and those that name only shipped files run, in a temporary folder;
  the README's own ``tsid`` commands parse too;
* the Python block of ``docs/reference/python.md`` runs as written (slow: one SISO
  study), and the README's Python block is made of its lines, in order;
* every line of the TOML block of ``docs/tutorial/first-identification.md`` is a line of
  ``examples/lsea_siso/study.toml``, in order (that study is run by
  ``tests/test_examples.py``);
* every path the README and the docs name in backticks is in the repository, and every
  relative link of theirs leads to a file that exists.
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
DOCS = REPO / "docs"
CLI_PAGE = DOCS / "reference" / "cli.md"
PYTHON_PAGE = DOCS / "reference" / "python.md"
TUTORIAL = DOCS / "tutorial" / "first-identification.md"


def _text(page: Path) -> str:
    return page.read_text(encoding="utf-8")


def _blocks(lang: str, text: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _command_lines(block: str) -> list[list[str]]:
    out = []
    for line in block.splitlines():
        command = line.split("  #")[0].strip()
        if command:
            out.append(shlex.split(command))
    return out


def _commands() -> list[list[str]]:
    (block,) = _blocks("bash", _text(CLI_PAGE))
    return _command_lines(block)


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


def test_the_readmes_tsid_commands_parse():
    parser = make_parser()
    commands = [
        argv
        for block in _blocks("bash", README)
        for argv in _command_lines(block)
        if argv[0] == "tsid"
    ]
    assert len(commands) >= 3
    for argv in commands:
        parser.parse_args(_fill(argv[1:]))


def test_every_tsid_command_of_the_docs_parses():
    parser = make_parser()
    commands = [
        (page, argv)
        for page in sorted(DOCS.rglob("*.md"))
        for block in _blocks("bash", _text(page))
        for argv in _command_lines(
            "\n".join(x for x in block.splitlines() if x.startswith("tsid "))
        )
    ]
    assert len(commands) >= 20
    for page, argv in commands:
        if argv[1:] == ["--version"]:
            continue
        try:
            parser.parse_args(_fill(argv[1:]))
        except SystemExit as error:  # argparse's way of refusing
            raise AssertionError((page.relative_to(REPO), argv)) from error


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
    (block,) = _blocks("toml", _text(TUTORIAL))
    source = (REPO / "examples" / "lsea_siso" / "study.toml").read_text().splitlines()
    _lines_in_order(block, source, "tutorial line not in the SISO study")


@pytest.mark.slow
def test_python_snippet_runs(workdir):
    (block,) = _blocks("python", _text(PYTHON_PAGE))
    namespace: dict = {}
    exec(compile(block, str(PYTHON_PAGE.relative_to(REPO)), "exec"), namespace)
    res = namespace["res"]
    assert res.success and (workdir / "results" / "siso" / "report.html").is_file()
    assert len(namespace["figures"]) == 4
    assert os.path.basename(str(res.study.fmu)) == "LSEA_SISO.fmu"


def test_the_readmes_python_block_is_made_of_the_python_pages_lines():
    (short,) = _blocks("python", README)
    (full,) = _blocks("python", _text(PYTHON_PAGE))
    _lines_in_order(short, full.splitlines(), f"README line not in {PYTHON_PAGE.name}")


def _lines_in_order(block: str, source: list[str], what: str) -> None:
    """Assert that every non-blank line of ``block`` is a line of ``source``, in order."""
    position = 0
    for line in block.splitlines():
        if not line.strip():
            continue
        assert line in source[position:], f"{what}: {line!r}"
        position = source.index(line, position) + 1


def _pages() -> list[Path]:
    return [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]


def test_every_path_the_readme_names_is_in_the_repository():
    # issue 26: it cited ../shared/seeds/, which a user of the package does not have
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert not re.findall(r"`\.\./[^`]*`|\]\(\.\./", text)
    for page in _pages():
        text = _text(page)
        for path in re.findall(
            r"`((?:examples|fmus|models|benchmarks|docs|tests|tsid_fmu)/[^`\s]*)`", text
        ):
            clean = path.split("::")[0].rstrip(".,:;)")
            if any(mark in clean for mark in ("*", "{", "NN", "<")):
                continue  # a pattern or a placeholder
            if clean.startswith("benchmarks/.cache/"):
                continue  # what a benchmark writes (git ignores it)
            assert (REPO / clean).exists(), (page.relative_to(REPO), path)


def test_every_relative_link_of_the_readme_and_the_docs_leads_to_a_file():
    for page in _pages():
        for target in re.findall(r"\]\(([^)\s]+)\)", _text(page)):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            path = (page.parent / target.split("#")[0]).resolve()
            assert path.exists(), (page.relative_to(REPO), target)
            assert REPO in path.parents or path == REPO, (page.relative_to(REPO), target)
