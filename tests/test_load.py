"""A finished run read back into Python (issue 26): ``tsid_fmu.load``, SciPy's ``res.x``
(an array in the order of ``res.names``) beside lmfit's ``res.params``, ``res.cov`` and
``res.jac``, and ``res.x_at(k)``; the checksums of the trail guard what is read."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest
from fmu_factory import lag_response, lag_study

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
    assert back.params == res.params and back.names == res.names
    np.testing.assert_array_equal(back.x, res.x)
    np.testing.assert_array_equal(back.cov, res.cov)
    np.testing.assert_array_equal(back.jac, res.jac)  # bit for bit, from jacobian.npy
    assert back.jac.dtype == res.jac.dtype and back.jac.shape == res.jac.shape
    assert back.fun == res.fun and back.nfev == res.nfev
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
    data["params"]["tau"] *= 2
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


def test_load_checks_the_jacobian_against_result_json(run, tmp_path):
    res, out = run
    data = json.loads((out / "result.json").read_text())
    assert data["jac"]["file"] == "jacobian.npy" and data["jac"]["shape"] == list(res.jac.shape)
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    changed = res.jac.copy()
    changed[0, 0] += 1.0
    np.save(copy / "jacobian.npy", changed)  # a valid array, not the one the run wrote
    with pytest.raises(StudyError, match=r"jacobian\.npy: changed or damaged"):
        load(copy)
    (copy / "jacobian.npy").unlink()
    with pytest.raises(StudyError, match=r"jacobian\.npy: missing, but result\.json lists it"):
        load(copy)


def test_load_without_the_study_files_still_reads_the_numbers(run, tmp_path):
    res, out = run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "study.toml").unlink()
    back = load(copy)
    assert back.study is None and back.params == res.params
    assert any("study is not attached" in w for w in back.warnings)
    attached = load(copy, study=res.study)
    assert attached.study is res.study and not set(attached.warnings) - set(res.warnings)


def test_x_is_an_array_in_the_order_of_names_and_params_the_dict(run):
    res, _ = run
    assert res.names == res.study.parameter_names == ["tau", "x0"]
    assert isinstance(res.params, dict) and list(res.params) == res.names
    assert isinstance(res.x, np.ndarray) and res.x.shape == (2,) and res.x.dtype == float
    assert res.x.tolist() == [res.params["tau"], res.params["x0"]]
    with pytest.raises(ValueError, match="read-only"):
        res.x[0] = -1.0  # SciPy's array, but not a way to change the result
    assert "names: ['tau', 'x0']" in repr(res) and "x: array(" in repr(res)
    # result.json holds what the attributes hold: names, x in their order, params by name
    data = json.loads((res.out_dir / "result.json").read_text())
    assert data["params"] == res.params
    assert data["names"] == res.names and data["x"] == list(res.x)


def test_cov_is_the_covariance_of_the_reported_standard_errors(run):
    res, _ = run
    u = res.uncertainty
    assert res.cov.shape == (2, 2)
    np.testing.assert_allclose(res.cov, res.cov.T)
    se = [u.std_error[n] for n in res.names]  # parameter units
    np.testing.assert_allclose(np.sqrt(np.diag(res.cov)), se, rtol=1e-12)
    rho = res.cov[0, 1] / np.sqrt(res.cov[0, 0] * res.cov[1, 1])
    assert rho == pytest.approx(u.correlation["tau"]["x0"], rel=1e-12)
    assert np.all(np.linalg.eigvalsh(res.cov) > 0)


def test_jac_is_the_residual_jacobian_in_parameter_units(run):
    res, out = run
    data = pd.read_csv(out.parent / "lag.csv")
    t, u = data["time"].to_numpy(), data["u"].to_numpy()
    assert res.jac.shape == (len(t), 2)  # one output: one residual per sample
    # against the exact response's derivatives: the same up to the residual scale
    tau, x0 = res.params["tau"], res.params["x0"]
    h = 1e-6
    d_tau = (lag_response(t, u, tau + h, x0) - lag_response(t, u, tau - h, x0)) / (2 * h)
    d_x0 = (lag_response(t, u, tau, x0 + h) - lag_response(t, u, tau, x0 - h)) / (2 * h)
    exact = np.column_stack([d_tau, d_x0])
    scale = np.sum(exact * res.jac) / np.sum(exact * exact)  # 1 / the residual scale
    assert scale > 0
    assert np.linalg.norm(res.jac - scale * exact) < 0.02 * np.linalg.norm(res.jac)


def test_x_at_gives_each_iterations_best_set(run):
    res, _ = run
    assert res.nit >= 2
    for k, rec in enumerate(res.iterations, start=1):
        assert res.x_at(k) == {n: rec.best_x[n] for n in res.names}
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
    assert back.params == res.params and back.study is None
    assert any("no checksum" in w for w in back.warnings)
    assert any("study is not attached" in w for w in back.warnings)


def test_cov_of_an_undetermined_parameter_is_infinite_on_the_diagonal():
    from tsid_fmu import IdentificationResult
    from tsid_fmu.uncertainty.intervals import Uncertainty

    u = Uncertainty(
        values={"a": 1.0, "b": 2.0},
        std_error={"a": 0.1, "b": math.inf},
        correlation={"a": {"a": 1.0, "b": 0.3}, "b": {"a": 0.3, "b": 1.0}},
    )
    res = IdentificationResult(
        params={"a": 1.0, "b": 2.0}, fun=1.0, nfev=1, success=True, status=0, message="m"
    )
    res.uncertainty = u
    cov = res.cov
    assert cov[0, 0] == pytest.approx(0.01) and cov[1, 1] == math.inf
    assert math.isnan(cov[0, 1]) and math.isnan(cov[1, 0])
