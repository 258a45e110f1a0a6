"""``docs/how-to/input-delay.md``: its snippet is a study the loader accepts, and the
refusal it quotes is what the loader says (issue 64, "docs true by construction").

Fast: the SISO example's study with the page's ``delay(F_m)`` entry added is loaded and
checked against the FMU; nothing is simulated. That a delay is identified is
``tests/test_delay.py`` (slow), whose figures the page quotes.
"""

from __future__ import annotations

import re
from pathlib import Path

from tsid_fmu.cli import main
from tsid_fmu.study import load_study

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "how-to" / "input-delay.md").read_text(encoding="utf-8")
SISO = ROOT / "examples" / "lsea_siso" / "study.toml"


def _entry() -> str:
    (block,) = re.findall(r"```toml\n(.*?)```", PAGE, re.DOTALL)
    (line,) = [x for x in block.splitlines() if x.startswith('"delay(')]
    return line


def _study(tmp_path: Path, entry: str) -> Path:
    text = SISO.read_text(encoding="utf-8").replace("../../", f"{SISO.parents[2].as_posix()}/")
    text = text.replace(
        'file = "measured.csv"', f'file = "{(SISO.parent / "measured.csv").as_posix()}"'
    )
    path = tmp_path / "study.toml"
    path.write_text(text.rstrip("\n") + "\n" + entry + "\n", encoding="utf-8")
    return path


def test_the_pages_delay_entry_loads_beside_the_siso_parameters(tmp_path):
    study = load_study(_study(tmp_path, _entry()))
    (delay,) = [p for p in study.parameters if p.name == "delay(F_m)"]
    assert list(delay.levels) == [-1e-3, -0.5e-3, 0.0, 0.5e-3, 1e-3] and delay.unit == "s"
    assert delay.bounds == (-2e-3, 2e-3)


def test_a_delay_of_no_input_is_refused_as_the_page_quotes(tmp_path, capsys):
    """Refused when the study starts, before any simulation (``tsid identify`` exits 2)."""
    quoted = re.search(r"refused with\s+`([^`]+)`", PAGE)[1]
    pattern = re.escape(quoted).replace(r"\.\.\.", ".*").replace("X", "x_m")
    study = _study(tmp_path, _entry().replace("delay(F_m)", "delay(x_m)"))
    rc = main(["identify", str(study), "--out", str(tmp_path / "out"), "-q", "--no-plots"])
    err = capsys.readouterr().err
    assert rc == 2 and re.search(pattern, err), (err, quoted)
