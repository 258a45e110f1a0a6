"""The capture of what an FMU prints survives an FMU that closes its descriptors (issue 66, 7).

A runtime may close descriptors it does not own: the capture file's, or the saved
copies of stdout and stderr (one that closes every descriptor above 2). That was a
worker traceback, ``OSError: [Errno 9] Bad file descriptor``; now the call's result
stands and what it printed is one line saying the FMU closed its output descriptor.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tsid_fmu.fmu.native import CLOSED_NOTE, NativeOutput

REPO = Path(__file__).resolve().parents[1]


def test_an_fmu_that_closes_the_capture_file_is_noted_not_a_traceback(capfd):
    out = NativeOutput(echo=True)

    def closing() -> int:
        os.write(1, b"hello\n")
        assert out._fd is not None
        os.close(out._fd)
        return 5

    try:
        assert out.call(closing) == 5
        assert out.text == CLOSED_NOTE
        assert "the FMU closed its output descriptor" in out.reason()
        assert out.call(lambda: os.write(1, b"again\n")) == 6  # a new file next time
        assert out.text == "again\n"
    finally:
        out.close()
    err = capfd.readouterr().err
    assert "the FMU closed its output descriptor" in err and "again" in err


_CLOSE_ALL = """
import os, sys
from tsid_fmu.fmu.native import NativeOutput
out = NativeOutput(echo=True)

def close_all():
    os.write(1, b"lost\\n")
    os.closerange(3, 4096)  # the capture file and the saved stdout and stderr
    return 7

result = out.call(close_all)
with open(sys.argv[1], "w") as f:
    f.write(f"{result} {out.text}")
print("after", flush=True)  # stdout is /dev/null now: no error either
"""


def test_an_fmu_that_closes_every_descriptor_above_2_leaves_a_note(tmp_path):
    """The saved stdout and stderr are gone: the note, and no traceback."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    said = tmp_path / "said.txt"
    done = subprocess.run(
        [sys.executable, "-c", _CLOSE_ALL, str(said)],
        capture_output=True, text=True, env=env, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "Bad file descriptor" not in done.stderr
    assert said.read_text() == f"7 {CLOSED_NOTE}"
