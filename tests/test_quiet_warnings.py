"""No library warning reaches stderr under ``-q`` (issue 62, item 7).

NumPy's overflow RuntimeWarnings came from ``doe/sn.py``, ``taguchi/surface.py`` and
``numerics/fdstep.py`` when a run's cost or residuals passed 1e154: those sites now
compute without them (their results were inf or clipped already, or NaN where they now
are not). What any other library still warns under ``-q`` goes to the output folder's
``warnings.log``.
"""

from __future__ import annotations

import importlib
import warnings

import numpy as np
import pytest

from tsid_fmu.cli import main
from tsid_fmu.cli_warnings import WARNINGS_LOG
from tsid_fmu.doe.sn import SN_CAP, sn_larger_the_better, sn_nominal_the_best, sn_smaller_the_better
from tsid_fmu.errors import StudyError
from tsid_fmu.numerics.fdstep import MAX_STEP, solver_noise, steps_for
from tsid_fmu.search.taguchi.surface import principal_axes
from tsid_fmu.trail.owner import FINGERPRINT

HUGE = 1e200
"""A response whose square overflows."""


@pytest.fixture
def strict():
    """Make every warning an error inside the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def test_sn_ratios_of_huge_responses_give_no_warning(strict):
    # in logarithms: -20 log10(1e200), not an overflow clipped to a floor (issue 64)
    assert sn_smaller_the_better([[HUGE, HUGE], [1.0, 1.0]]).tolist() == [-4000.0, 0.0]
    assert sn_larger_the_better([[1 / HUGE, 1 / HUGE], [1.0, 1.0]]).tolist() == [-4000.0, 0.0]
    # mean**2 / var was inf / inf = NaN; it does not depend on the scale
    sn = sn_nominal_the_best([[3 * HUGE, 4 * HUGE], [3.0, 4.0]])
    assert np.all(np.isfinite(sn)) and sn[0] == pytest.approx(sn[1])
    # a zero mean is as bad as a failed row: 20 dB below the other
    zero_mean = sn_nominal_the_best([[HUGE, -HUGE], [1.0, 2.0]])
    assert zero_mean[0] == pytest.approx(zero_mean[1] - 20.0)
    assert sn_smaller_the_better([[0.0, 0.0], [1.0, 1.0]])[0] == SN_CAP


def test_principal_axes_of_huge_residuals_are_none_without_a_warning(strict):
    rng = np.random.default_rng(0)
    points = [(rng.normal(size=2), HUGE * rng.normal(size=10)) for _ in range(6)]
    assert principal_axes(points, np.zeros(2)) is None  # was NaN axes, and a warning
    small = [(s, r / HUGE) for s, r in points]
    vectors, curvatures = principal_axes(small, np.zeros(2))
    assert np.all(np.isfinite(vectors)) and np.all(np.isfinite(curvatures))


def test_finite_difference_steps_of_huge_residuals_give_no_warning(strict):
    rng = np.random.default_rng(1)
    for scale in (1e160, 1e307):
        noise = solver_noise(
            lambda points, scale=scale: [scale * rng.normal(size=50) for _ in points],
            np.zeros(3), scale * rng.normal(size=50), 1e-3, np.ones(3),
        )  # fmt: skip
        assert noise > 0  # scales with the residuals (inf where past the float range)
    assert steps_for(np.full(3, 1e-6), HUGE * rng.normal(size=(50, 3)), 1.0).tolist() == [1e-6] * 3
    assert steps_for(np.full(3, 1e-6), rng.normal(size=(50, 3)), np.inf).tolist() == [MAX_STEP] * 3


def _warning_then_error(folder, owned):
    """A stand-in for ``identify``: the folder, a NumPy overflow, then an error."""

    def identify(study, out, **_):
        out.mkdir(parents=True, exist_ok=True)
        if owned:
            (out / FINGERPRINT).write_text("{}")
        _ = np.float64(HUGE) ** 2  # RuntimeWarning: overflow encountered
        raise StudyError("stopped")

    return identify


@pytest.mark.parametrize("owned", [True, False])
def test_identify_q_keeps_warnings_off_stderr_and_in_the_log(tmp_path, capfd, monkeypatch, owned):
    out = tmp_path / "out"
    monkeypatch.setattr(
        importlib.import_module("tsid_fmu.identify"), "identify", _warning_then_error(out, owned)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("always")  # as a first run shows it, whatever pytest's filters
        code = main(["identify", str(tmp_path / "s.toml"), "--out", str(out), "-q"])
    assert code == 2
    assert capfd.readouterr().err == "tsid: error: stopped\n"
    log = out / WARNINGS_LOG
    if owned:
        text = log.read_text(encoding="utf-8")
        assert "RuntimeWarning: overflow encountered" in text and text.count("\n") == 1
    else:  # a folder that is not the study's gets no file (the next run would refuse it)
        assert not log.exists()


_SCRIPT = """
import importlib, sys
from pathlib import Path
import numpy as np
from tsid_fmu.cli import main
from tsid_fmu.errors import StudyError

def identify(study, out, **_):
    out.mkdir(parents=True, exist_ok=True)
    (out / "fingerprint.json").write_text("{}")
    _ = np.float64(1e200) ** 2
    raise StudyError("stopped")

importlib.import_module("tsid_fmu.identify").identify = identify
sys.exit(main(["identify", "s.toml", "--out", sys.argv[1], *sys.argv[2:]]))
"""


@pytest.mark.parametrize("quiet", [True, False])
def test_a_process_prints_the_warning_only_without_q(tmp_path, quiet):
    """As a user's shell sees it: Python's own warning printer, no pytest in between."""
    import subprocess
    import sys

    out = tmp_path / "out"
    args = [sys.executable, "-c", _SCRIPT, str(out), *(["-q"] if quiet else [])]
    done = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode == 2
    if quiet:
        assert done.stderr == "tsid: error: stopped\n"
        assert "RuntimeWarning: overflow" in (out / WARNINGS_LOG).read_text(encoding="utf-8")
    else:
        assert "RuntimeWarning: overflow" in done.stderr
        assert not (out / WARNINGS_LOG).exists()


def test_a_combination_with_a_member_at_zero_gives_no_warning(strict):
    """A member at 1e-320 has an infinite relative scale; ``nan_to_num`` made it 1.8e308
    and the combination's norm overflowed (a RuntimeWarning on stderr in the structure
    benchmark's law-1 study). Such a member is left out of the relative error."""
    from tsid_fmu.doe.options import LevelingOptions
    from tsid_fmu.numerics.space import Space
    from tsid_fmu.uncertainty.intervals import uncertainty
    from tsid_fmu.uncertainty.sensitivity import Sensitivities

    t = np.linspace(0.0, 1.0, 40)
    jac = np.stack([np.sin(3 * t), np.cos(2 * t)], axis=-1)[:, None, :]
    sens = Sensitivities(["a", "b"], [0.01 * np.sin(7 * t)[:, None]], [jac], ["e"], [["y"]])
    space = Space({"a": [0.5, 1.5], "b": [0.0, 1.0]}, {"a": (0, 10), "b": (0, 10)},
                  LevelingOptions(scale="linear"))  # fmt: skip
    found = uncertainty(sens, space, {"a": 1.0, "b": 1e-320})
    assert found is not None and found.combinations
    assert all(not np.isinf(c["percent"]) for c in found.combinations)
