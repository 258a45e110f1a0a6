"""Properties of the study loader over the newer keys (issue 44, Hypothesis).

Any value at any key among the discrete choices, a choice among FMU files, windows,
warm-up, window weights, ``initial`` and the sampled uncertainty: the study loads, or
it is refused with a :class:`~tsid_fmu.errors.TsidError` (one line naming the key at
the command line), never another exception.
"""

from __future__ import annotations

import copy
import json
import math
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_choices import DESCRIPTION

from tsid_fmu.errors import TsidError
from tsid_fmu.study import Study, load_study

TEMPLATE: dict[str, dict[str, Any]] = {
    "study": {"fmu": "Switches.fmu", "name": "newer keys"},
    "data": {
        "file": "d.csv",
        "outputs": {"y": "y"},
        "windows": [[0.1, 0.5], [0.6, 0.9]],
        "warmup": 0.05,
        "window_weights": [1.0, 2.0],
        "initial": {"D": "from_data:y"},
    },
    "method": {"cost": "sse", "uncertainty": "bootstrap", "uncertainty_replicates": 50},
    "parameters": {
        "K": {"levels": [1.0, 2.0, 3.0], "min": 0.0},
        "masses": {"choices": [1, 2]},
        "friction": {"choices": ["coulomb", "viscous"]},
        "damping_on": {"choices": [True, False]},
        "model": {"fmus": ["Switches.fmu", "Switches2.fmu"]},
    },
}
HOSTILE = st.sampled_from(
    [1e308, -1e308, 5e-324, -1, 0, 2**31, 2**63, 10**400, float("nan"), float("inf"), "",
     "x", "from_data:nope", "identify", "Switches.fmu", "../../etc/passwd", True, [], [1],
     [1, 1], [[1.0, 0.5]], [[0.0, 1e308]], {"a": 1}, {}, [True, 2], ["a", 1]]
)  # fmt: skip


def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(x)}" for k, x in v.items()) + "}"
    return json.dumps(v) if isinstance(v, str) else str(v)


def _text(doc: dict) -> str:
    return "\n".join(
        f"[{table}]\n" + "".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in body.items())
        for table, body in doc.items()
    )


def _paths(doc: Any, prefix: tuple = ()) -> Iterator[tuple]:
    if isinstance(doc, dict) and doc:
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list) and doc:
        yield prefix  # the list as a whole
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))
    else:
        yield prefix


@st.composite
def hostile_studies(draw) -> str:
    doc = copy.deepcopy(TEMPLATE)
    for path in draw(st.lists(st.sampled_from(list(_paths(TEMPLATE))), min_size=1,
                              max_size=3, unique=True)):  # fmt: skip
        parent: Any = doc
        try:
            for key in path[:-1]:
                parent = parent[key]
            parent[path[-1]] = copy.deepcopy(draw(HOSTILE))
        except (KeyError, IndexError, TypeError):  # an earlier draw replaced a parent
            continue
    return _text(doc)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("newer")
    for name in ("Switches", "Switches2"):
        with zipfile.ZipFile(d / f"{name}.fmu", "w") as z:
            z.writestr("modelDescription.xml", DESCRIPTION.format("{1234}"))
    (d / "d.csv").write_text("time,y\n0,0\n0.25,0.5\n0.5,1\n0.75,1.5\n1,2\n")
    return d


def test_the_template_itself_loads(folder):
    (folder / "t.toml").write_text(_text(TEMPLATE))
    study = load_study(folder / "t.toml")
    assert isinstance(study, Study) and len(study.choices) == 4


@pytest.mark.slow
@settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(text=hostile_studies())
def test_any_value_at_a_newer_key_loads_or_is_a_tsid_error(folder, text):  # fmt: skip
    path = folder / "s.toml"
    path.write_text(text)
    try:
        study = load_study(path)
    except TsidError as exc:
        assert "\n" not in str(exc).strip() or "Did you mean" in str(exc), str(exc)
        return
    # what loads keeps the rules the refusals stand for
    for c in study.choices:
        assert all(-(2**31) <= v < 2**31 for v in c.values), c
    for e in study.experiments:
        assert all(w <= 1e12 for w in e.window_weights or []), e.window_weights
        assert not set(e.initial) & set(study.start_values), e.initial
    if study.method.uncertainty == "analytic":
        assert study.method.uncertainty_replicates == 100
