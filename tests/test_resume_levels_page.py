"""The ``next_levels.toml`` snippets of ``docs/how-to/resume-and-edit-levels.md`` are what
tsid writes and reads (issue 64, "docs true by construction").

The page shows the rotated file the SISO example writes after its first iteration
(``[centre]`` and ``[[factors]]``) and a ``[levels]`` table that may replace it. Both
must be read by :func:`~tsid_fmu.trail.levels.read_next_levels` against the SISO study's
parameters, and the rotated one must have the tables and keys, and the comment header,
that :func:`~tsid_fmu.trail.levels.write_next_levels` writes for a rotated frame (fast:
nothing is simulated).
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame
from tsid_fmu.study import load_study
from tsid_fmu.trail.levels import read_next_levels, write_next_levels

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "how-to" / "resume-and-edit-levels.md"
STUDY = ROOT / "examples" / "lsea_siso" / "study.toml"


def _blocks() -> list[str]:
    text = PAGE.read_text(encoding="utf-8")
    section = text[text.index("## Editing the next levels") :]
    return re.findall(r"```toml\n(.*?)```", section, re.DOTALL)


def _space() -> Space:
    study = load_study(STUDY)
    return Space(study.first_levels(), study.bounds(), study.method.leveling)


def _shape(doc: dict) -> dict:
    """The tables and keys of a parsed ``next_levels.toml``, without the numbers."""
    out = {k: sorted(v) for k, v in doc.items() if isinstance(v, dict)}
    out.update(
        {
            k: [{key: sorted(val) if isinstance(val, dict) else None for key, val in f.items()}
                for f in v]
            for k, v in doc.items() if isinstance(v, list)
        }
    )  # fmt: skip
    return out


def _written_rotated(space: Space, tmp_path: Path) -> str:
    dim = space.dim
    q, _ = np.linalg.qr(np.arange(1.0, dim * dim + 1).reshape(dim, dim) + np.eye(dim))
    factors = [Factor(f"A{k + 1}", q[:, k], np.array([-0.1, 0.0, 0.1])) for k in range(dim)]
    frame = Frame(np.zeros(dim), factors, anchor=space.to_x(np.zeros(dim)))
    decisions = [SimpleNamespace(name=n, case="Case 1", reason="r") for n in space.names]
    record = SimpleNamespace(
        index=1, stage="taguchi", decision=SimpleNamespace(parameters=decisions)
    )
    return write_next_levels(tmp_path / "next_levels.toml", record, space, frame, "Case 1: n")


def test_the_page_shows_a_rotated_file_and_a_levels_table():
    blocks = _blocks()
    assert len(blocks) == 2, blocks
    rotated, levels = (tomllib.loads(b) for b in blocks)
    assert set(rotated) == {"centre", "factors"} and set(levels) == {"levels"}


def test_the_rotated_snippet_is_read_and_shaped_as_tsid_writes_it(tmp_path):
    space = _space()
    snippet = _blocks()[0]
    written = _written_rotated(space, tmp_path)
    assert _shape(tomllib.loads(snippet)) == _shape(tomllib.loads(written))
    # the comment lines tsid writes before the tables, as the page quotes them
    head = [line for line in written.splitlines() if line.startswith("#")][1:]
    assert [line for line in snippet.splitlines() if line.startswith("#")][1:] == head
    path = tmp_path / "edited.toml"
    path.write_text(snippet, encoding="utf-8")
    frame = read_next_levels(path, space)
    assert not frame.axis_aligned and len(frame.factors) == space.dim
    assert frame.anchor == tomllib.loads(snippet)["centre"]


def test_the_levels_snippet_replaces_it_with_those_exact_levels(tmp_path):
    space = _space()
    snippet = _blocks()[1]
    path = tmp_path / "edited.toml"
    path.write_text(snippet, encoding="utf-8")
    frame = read_next_levels(path, space)
    assert frame.axis_aligned
    want = {n: sorted(v) for n, v in tomllib.loads(snippet)["levels"].items()}
    got = frame.level_values(space)
    assert {n: [float(v) for v in got[n]] for n in want} == want
