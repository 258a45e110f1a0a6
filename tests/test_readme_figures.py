"""The README's figures match a fresh run of the commands beside them (issue 26).

Each test reads the command and the figures out of ``README.md`` and runs the command
(the SISO example, about 20 s each on 2 shared cores), so it fails when either drifts:

* "Set up and run": the first command's stdout, line for line (the numbers included),
  its exit status, the stage counts, the errors against the truth and "every 95 %
  interval holds the truth" of the paragraph after it;
* the progress capture: each of its lines is a line ``identify(..., progress=True)``
  prints, in order, with the timings (``2.4 s``) left out of the comparison; the status
  bar (drawn only on a terminal) is not compared.
"""

from __future__ import annotations

import math
import re
import shlex
from pathlib import Path

import pytest

from tsid_fmu import identify, load
from tsid_fmu.cli import main

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text(encoding="utf-8")
FIRST = "The first command prints progress on stderr and this on stdout"


def _code_after(marker: str, start: int = 0) -> tuple[str, int]:
    """Return the fenced block that follows ``marker`` and the index after it."""
    at = README.index(marker, start)
    body = README.index("\n", README.index("```", at)) + 1
    end = README.index("```", body)
    return README[body:end], end + 3


def _prose(after: int) -> str:
    """Return the paragraph after position ``after``, on one line."""
    text = README[after:].lstrip("\n")
    return " ".join(text[: text.index("\n\n")].split())


def _readme_command() -> list[str]:
    section = README[README.index("## Set up and run") :]
    block, _ = _code_after("Run the SISO example", README.index("## Set up and run"))
    assert section.index("Run the SISO example") < section.index(FIRST)
    return shlex.split(block.split("&&")[-1].strip())


def _timeless(line: str) -> str:
    """``line`` with its timings (``14.8 s``) replaced by ``T s``."""
    return re.sub(r"\b\d+(\.\d+)? s\b", "T s", line)


def _numbers(text: str) -> list[str]:
    return re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    for name in ("examples", "fmus"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.slow
def test_the_first_commands_output_is_the_readmes(workdir, capsys):
    argv = _readme_command()
    assert argv[:2] == ["tsid", "identify"] and "--out" in argv, argv
    expected, end = _code_after(FIRST)
    status = int(re.search(r"\(exit status (\d)\)", expected).group(1))
    assert main(argv[1:]) == status
    printed = capsys.readouterr().out.splitlines()
    printed = [line for line in printed if not line.startswith("report: ")]  # its path
    # the numbers first, for a short message; then the text
    assert _numbers("\n".join(printed)) == _numbers(expected)
    assert printed == expected.rstrip("\n").splitlines()
    # the paragraph after it: stage counts, errors against the truth, the intervals
    text = _prose(end)
    res = load(argv[argv.index("--out") + 1])
    taguchi = res.stages[0]
    found = re.search(r"\((\d+) iterations, (\d+) simulations", text)
    assert (int(found[1]), int(found[2])) == (len(taguchi.records), taguchi.nfev), text
    found = re.search(r"the refinement does not lower the cost \((\d+) simulations\)", text)
    assert found and int(found[1]) == res.stages[1].nfev, text
    assert res.stages[1].cost == taguchi.cost
    found = re.search(r"predicts a decrease of ([\d.e-]+) of the cost", text)
    assert found and f"({found[1]} of the cost" in "\n".join(printed), text
    stated = text[text.index("Truth:") : text.index("The answer is")]
    truth = {m[1]: float(m[2]) for m in re.finditer(r"(\w+) ([\d.]+) [\w./]+[,.]", stated)}
    assert set(truth) == set(res.names), truth
    answer = text[text.index("The answer is") :]
    for name, value in truth.items():
        quoted = re.search(rf"{name} ([-+]?\d+\.(\d+)) %", answer)
        assert quoted, (name, answer)
        error = f"{100 * (res.params[name] / value - 1):.{len(quoted[2])}f}"
        error = error.lstrip("-") if float(error) == 0 else error
        assert error == quoted[1].lstrip("+"), (name, error, quoted[1])
    assert "every 95 % interval holds the truth" in text
    said_open = {(m[1], m[2]) for m in re.finditer(r"(\w+)'s (lower|upper)\s+end is open", text)}
    for name, value in truth.items():
        low, high = res.intervals[name]
        is_open = {(name, side) for side, end in (("lower", low), ("upper", high)) if end is None}
        assert is_open == {o for o in said_open if o[0] == name}, (name, low, high)
        assert (low is None or low <= value) and (high is None or value <= high), name
        if not is_open:
            assert math.isfinite(res.cov[res.names.index(name), res.names.index(name)])


@pytest.mark.slow
def test_the_progress_capture_is_what_identify_prints(workdir, capsys):
    marker = "Captured from `tsid identify"
    at = README.index(marker)
    command = " ".join(README[at : README.index("`", at + len(marker))].split())
    argv = shlex.split(command.split("`", 1)[1])
    assert argv[:3] == ["tsid", "identify", "examples/lsea_siso/study.toml"], argv
    iterations = int(argv[argv.index("--max-iterations") + 1])
    workers = int(argv[argv.index("--workers") + 1])
    during, end = _code_after(marker)
    after, _ = _code_after("and once the study ends:", end)
    expected = [
        line
        for line in (during + after).splitlines()
        if line.strip() and "[#" not in line  # the status bar: a terminal's only
    ]
    identify(argv[2], workdir / "out", max_iterations=iterations, workers=workers, progress=True)
    printed = [_timeless(line) for line in capsys.readouterr().err.splitlines()]
    position = 0
    for line in expected:
        # "..." in a quoted line stands for text left out
        pattern = ".*?".join(map(re.escape, _timeless(line).split(" ... ")))
        hits = [i for i in range(position, len(printed)) if re.fullmatch(pattern, printed[i])]
        assert hits, f"README line not printed (in order): {line!r}\n" + "\n".join(printed)
        position = hits[0] + 1
