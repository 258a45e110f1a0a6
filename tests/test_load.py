"""A finished run read back into Python (issue 26): ``tsid_fmu.load``, ``res.params``
and ``res.x_at(k)``; the checksums of the trail guard what is read."""

from __future__ import annotations

import json
import math
import shutil

import pytest
from fmu_factory import lag_study

import tsid_fmu
from tsid_fmu import StudyError, identify, load


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("lag")
    study = lag_study(d, name="lag", max_iterations=4, replicates=1)
    path = study.to_toml(d / "study" / "lag.toml")
    res = identify(path, d / "out", plots=False, workers=1)
    return res, d / "out"


def test_load_is_at_the_package_root():
    assert tsid_fmu.load is load and "load" in tsid_fmu.__all__


def test_load_gives_back_what_identify_returned(run):
    res, out = run
    back = load(out)
    assert back.x == res.x and back.fun == res.fun and back.nfev == res.nfev
    assert (back.status, back.success, back.message, back.nit) == (
        res.status,
        res.success,
        res.message,
        res.nit,
    )
    assert back.intervals == res.intervals and back.weak == res.weak
    assert back.warnings == res.warnings and back.fit == res.fit
    assert [s.to_dict() for s in back.stages] == [s.to_dict() for s in res.stages]
    assert len(back.iterations) == len(res.iterations) == res.nit
    assert [r.best_cost for r in back.iterations] == [r.best_cost for r in res.iterations]
    assert back.uncertainty.relative == pytest.approx(res.uncertainty.relative)
    assert back.contribution == res.contribution
    assert back.out_dir == out
    # the study as run is attached: its paths start where the study file was
    assert back.study == res.study
    assert back.parameters_frame().equals(res.parameters_frame())
    assert back.to_pandas().equals(res.to_pandas())


def test_load_refuses_a_changed_or_missing_file(run, tmp_path):
    _, out = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    data = json.loads((copy / "result.json").read_text())
    assert isinstance(data["digest"], str)
    data["x"]["tau"] *= 2
    (copy / "result.json").write_text(json.dumps(data))
    with pytest.raises(StudyError, match=r"result.json: the result was changed or damaged"):
        load(copy)
    shutil.rmtree(copy)
    shutil.copytree(out, copy)
    runs = copy / "iteration_01" / "runs.csv"
    runs.write_text(runs.read_text().replace("0", "1", 1))
    with pytest.raises(StudyError, match=r"runs.csv: changed or damaged"):
        load(copy)
    with pytest.raises(StudyError, match="no such folder"):
        load(tmp_path / "nowhere")
    (copy / "result.json").unlink()
    with pytest.raises(StudyError, match=r"no result\.json"):
        load(copy)


def test_load_without_the_study_files_still_reads_the_numbers(run, tmp_path):
    res, out = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "study.toml").unlink()
    back = load(copy)
    assert back.study is None and back.x == res.x
    assert any("study is not attached" in w for w in back.warnings)
    attached = load(copy, study=res.study)
    assert attached.study is res.study and not set(attached.warnings) - set(res.warnings)


def test_params_is_a_plain_dict_and_x_is_unchanged(run):
    res, _ = run
    assert type(res.params) is dict and res.params == res.x
    res.params["tau"] = -1.0  # a copy: the result is not changed through it
    assert res.x["tau"] != -1.0
    assert type(res.x) is dict


def test_x_at_gives_each_iterations_best_set(run):
    res, _ = run
    assert res.nit >= 2
    for k, rec in enumerate(res.iterations, start=1):
        assert res.x_at(k) == {n: rec.best_x[n] for n in res.x}
    assert res.x_at(-1) == res.x_at(res.nit)
    assert res.x_at(-res.nit) == res.x_at(1)
    assert all(math.isfinite(v) for v in res.x_at(1).values())
    for bad in (0, res.nit + 1, -res.nit - 1):
        with pytest.raises(IndexError, match=f"iteration {bad}"):
            res.x_at(bad)
    with pytest.raises(TypeError):
        res.x_at("1")


def test_a_result_json_of_an_older_version_is_read_with_a_warning(run, tmp_path):
    res, out = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    data = json.loads((copy / "result.json").read_text())
    del data["digest"], data["study_folder"]
    (copy / "result.json").write_text(json.dumps(data))
    back = load(copy)
    assert back.x == res.x and back.study is None
    assert any("no checksum" in w for w in back.warnings)
    assert any("study is not attached" in w for w in back.warnings)
