"""``Study.from_toml(s.to_toml(p)) == s`` for any study (issue 26), checked with
Hypothesis; and ``to_toml`` into a folder that does not exist yet."""

from __future__ import annotations

import os
import string
import tempfile
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tsid_fmu import ContributionOptions, Experiment, Method, Parameter, Phase, Study
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate.cost import COSTS

NAME = st.text(string.ascii_letters + string.digits + "_.[]()- ", min_size=1, max_size=6)
TEXT = st.text(st.characters(codec="utf-8", categories=["L", "N", "P", "S", "Zs"]), max_size=8)
NUMBER = st.floats(-1e12, 1e12, allow_nan=False, allow_infinity=False)
POSITIVE = st.floats(1e-6, 1e6)
UNIT = st.floats(0.001, 0.999)
MAYBE = st.none() | POSITIVE


@st.composite
def parameters(draw):
    names = draw(st.lists(NAME, min_size=1, max_size=4, unique=True))
    out = []
    for name in names:
        levels = draw(st.lists(NUMBER, min_size=3, max_size=3, unique=True))
        low = draw(st.none() | st.floats(0, 1e3).map(lambda d, lv=levels: min(lv) - d))
        high = draw(st.none() | st.floats(1e-3, 1e3).map(lambda d, lv=levels: max(lv) + d))
        if low is not None and high is not None and low >= high:
            low = None
        out.append(Parameter(name, levels, min=low, max=high, unit=draw(TEXT)))
    return out


@st.composite
def windows(draw):
    """No windows, or 1-3 disjoint spans in time order, a warm-up and maybe weights."""
    ends = sorted(draw(st.lists(st.floats(0, 1e4), min_size=0, max_size=6, unique=True)))
    spans = [ends[i : i + 2] for i in range(0, len(ends) - 1, 2)]
    if not spans:
        return {"warmup": draw(st.sampled_from([0.0, 0.5]))}
    warmup = draw(
        st.floats(0, 10) | st.lists(st.floats(0, 10), min_size=len(spans), max_size=len(spans))
    )
    weights = draw(st.none() | st.lists(POSITIVE, min_size=len(spans), max_size=len(spans)))
    return {"windows": spans, "warmup": warmup, "window_weights": weights}


@st.composite
def experiments(draw, folder: Path):
    count = draw(st.integers(1, 2))
    names = draw(st.lists(NAME.filter(str.strip), min_size=count, max_size=count, unique=True))
    out = []
    for i, name in enumerate(names):
        data = folder / "data" / f"d{i}.csv"
        data.parent.mkdir(parents=True, exist_ok=True)
        data.write_text("time,u,y\n0,0,0\n")
        given = os.path.relpath(data) if draw(st.booleans()) else data
        ins = draw(st.lists(NAME, max_size=2, unique=True))
        outs = draw(st.lists(NAME, min_size=1, max_size=2, unique=True))
        weights = draw(st.none() | st.fixed_dictionaries({o: POSITIVE for o in outs}))
        out.append(
            Experiment(
                data=str(given) if draw(st.booleans()) else given,
                inputs={k: draw(NAME) for k in ins},
                outputs={k: draw(NAME) for k in outs},
                name=name,
                time_column=draw(st.sampled_from(["time", "t", "Time [s]"])),
                derived=draw(st.dictionaries(NAME, st.sampled_from(["a - b", "der(x)"]))),
                weights=weights,
                start_values=draw(st.dictionaries(NAME, NUMBER, max_size=2)),
                # ":" is in no NAME: these never clash with a parameter or start value
                initial={
                    f"s:{k}": "from_data:" + draw(NAME) for k in draw(st.lists(NAME, max_size=2))
                },
                sample_time=draw(MAYBE),
                role="identify" if i == 0 else draw(st.sampled_from(["identify", "validate"])),
                hold={k: draw(st.sampled_from(["previous", "linear"])) for k in ins[:1]},
                noise={k: draw(POSITIVE) for k in outs[:1]} if draw(st.booleans()) else {},
                **draw(windows()),
            )
        )
    return out


METHODS = st.builds(
    Method,
    cost=st.sampled_from(sorted(COSTS)),
    weighting=st.sampled_from(["none", "noise"]),
    replicates=st.integers(1, 5),
    input_noise=st.floats(0, 0.5),
    seed=st.integers(0, 2**31),
    max_iterations=st.integers(1, 50),
    max_simulations=st.none() | st.integers(1, 10**6),
    selection=st.sampled_from(["auto", "main_effects", "best_run"]),
    rotate=st.booleans(),
    max_reruns=st.integers(0, 5),
    interface=st.sampled_from([None, "auto", "cs", "me"]),
    step=st.none() | st.floats(1e-9, 10),
    tolerance=UNIT,
    fidelity=st.booleans(),
    leveling=st.builds(
        LevelingOptions,
        significance_db=st.floats(0, 10),
        shrink=UNIT,
        n_levels=st.none() | st.integers(2, 5),
        selective=st.booleans(),
        scale=st.sampled_from(["auto", "linear", "log"]),
        stall=st.integers(0, 5),
    ),
)


@st.composite
def studies(draw, folder: Path):
    fmu = folder / "models" / "plant.fmu"
    fmu.parent.mkdir(parents=True, exist_ok=True)
    fmu.write_bytes(b"PK")
    params = draw(parameters())
    names = [p.name for p in params]
    exps = draw(experiments(folder))
    phases = []
    if draw(st.booleans()):
        group = draw(st.lists(st.sampled_from(names), min_size=1, unique=True))
        name = draw(st.sampled_from(["", "first"]))
        limit = draw(st.none() | st.integers(1, 9))
        phases.append(Phase(group, [exps[0].name], name=name, max_iterations=limit))
    values = {n: [1.0, 2.0, 3.0] for n in names[:1]} if draw(st.booleans()) else {}
    method = draw(METHODS)
    return Study(
        fmu=os.path.relpath(fmu) if draw(st.booleans()) else fmu,
        parameters=params,
        experiments=exps,
        method=method,
        start_values=draw(st.dictionaries(NAME.filter(lambda n: n not in names), NUMBER)),
        interface=method.interface if method.interface not in (None, "auto") else "auto",
        step_size=method.step,
        name=draw(TEXT.filter(str.isprintable)),
        phases=phases,
        contribution=ContributionOptions(
            enabled=draw(st.booleans()),
            group_ratio=draw(st.floats(1.01, 10)),
            values=values,
            compare_ungrouped=draw(st.booleans()),
            refine_span=draw(UNIT),
        ),
    )


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_a_study_reads_back_equal_from_its_toml(data):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp).resolve()
        s = data.draw(studies(folder))
        # into a folder that does not exist yet
        path = s.to_toml(folder / "written" / "deeper" / "study.toml")
        back = Study.from_toml(path)
        assert back == s
        assert Study.from_toml(back.to_toml(folder / "again.toml")) == s


def test_to_toml_makes_the_folder_and_dataframe_studies_are_stable(tmp_path):
    (tmp_path / "plant.fmu").write_bytes(b"PK")
    frame = pd.DataFrame({"time": [0.0, 0.1], "u": [1.0, 2.0], "y": [0.5, 0.25]})
    s = Study(
        fmu=tmp_path / "plant.fmu",
        parameters=[Parameter("k", [1, 2, 3], min=0)],
        experiments=[Experiment(data=frame, inputs={"u": "u"}, outputs={"y": "y"}, name="step")],
    )
    path = s.to_toml(tmp_path / "new" / "folder" / "study.toml")
    assert (tmp_path / "new" / "folder" / "study_step.csv").is_file()
    back = Study.from_toml(path)
    # the frame became a file; from there on the round trip is exact
    assert back.experiments[0].data == (tmp_path / "new" / "folder" / "study_step.csv")
    assert Study.from_toml(back.to_toml(tmp_path / "other" / "s.toml")) == back


def test_paths_are_kept_resolved_whatever_form_they_are_given_in(tmp_path, monkeypatch):
    (tmp_path / "plant.fmu").write_bytes(b"PK")
    monkeypatch.chdir(tmp_path)
    s = Study(
        fmu="plant.fmu",
        parameters=[Parameter("k", [1, 2, 3])],
        experiments=[Experiment(data="sub/../d.csv", outputs={"y": "y"})],
    )
    assert s.fmu == tmp_path / "plant.fmu"
    assert s.experiments[0].data == tmp_path / "d.csv"
    assert s.experiments[0].name == "d"


def test_to_toml_onto_a_folder_is_refused(tmp_path):
    from tsid_fmu import StudyError

    (tmp_path / "plant.fmu").write_bytes(b"PK")
    s = Study(
        fmu=tmp_path / "plant.fmu",
        parameters=[Parameter("k", [1, 2, 3])],
        experiments=[Experiment(data=tmp_path / "d.csv", outputs={"y": "y"})],
    )
    with pytest.raises(StudyError, match="is a folder"):
        s.to_toml(tmp_path)
