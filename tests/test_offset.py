"""The load-cell offset models (idtool._model._offset) and the fit's choice between them.

The drift model must nest the constant one exactly (zero drift, same prediction), add
exactly the linear trend it claims to every block (checked against the blocks' own mean
times, not the model's formula), and be chosen where a bench drifts: on a simulated
bench whose offset drifts by 0.3 N/s (sd over pulls; about 3 N over a trace, five times
the load cell's noise) BIC prefers the drift model by about 850, its Kt lies within its
interval and every trace's drift rate is recovered. (Forced to the constant model, the
levels model reads the drift as scatter and discrepancy: Kt 24% off on seed 1, the mu
interval 3.7x as wide.)
"""

from __future__ import annotations

import dataclasses
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import idtool
from idtool import OFFSETS, ConstantOffset, DriftingOffset
from idtool._data._blocks import prepare_fit_data
from idtool._simulate._departures import departure_params


@pytest.fixture(scope="module")
def drifting_bench():
    params = departure_params("drift", 1)
    cell = dataclasses.replace(params.load_cell, offset_drift_sd_n_s=0.3)
    params = dataclasses.replace(params, load_cell=cell)
    dataset, truth = idtool.simulate_bench(params, seed=1)
    return params, dataset, truth


def _pair(dataset):
    data = prepare_fit_data(dataset, 50.0, 2)
    return (
        idtool.bench_model(data, offset="constant"),
        idtool.bench_model(data, offset="drift"),
    )


def test_registry_lists_the_simplest_model_first():
    # the fit nests each richer offset model in the first one's optimum
    assert OFFSETS.names() == ("constant", "drift")
    assert OFFSETS.get("constant") is ConstantOffset
    assert OFFSETS.get("drift") is DriftingOffset
    assert ConstantOffset.trace_params[0] == DriftingOffset.trace_params[0]


def test_zero_drift_is_the_constant_model(drifting_bench):
    _, dataset, _ = drifting_bench
    constant, drift = _pair(dataset)
    z0 = constant.z0()
    rng = np.random.default_rng(0)
    z0 = z0 + 0.05 * rng.standard_normal(z0.size)  # away from the start values
    by_name = dict(zip(constant.names, z0, strict=True))
    z1 = np.array([by_name.get(n, 0.0) for n in drift.names])  # drifts at 0 N/s
    a = np.asarray(constant.predict(jnp.asarray(z0)))
    b = np.asarray(drift.predict(jnp.asarray(z1)))
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)


def test_drift_adds_its_linear_trend_to_every_block(drifting_bench):
    _, dataset, _ = drifting_bench
    _, drift = _pair(dataset)
    d = drift.data
    z = drift.z0()
    rates = np.linspace(-0.4, 0.4, d.n_traces)  # [N/s]
    moved = z.copy()
    for i, tid in enumerate(d.trace_ids):
        moved[drift.names.index(f"offset_drift_n_s[{tid}]")] = rates[i] / 0.01  # its scale
    diff = np.asarray(drift.predict(jnp.asarray(moved)) - drift.predict(jnp.asarray(z)))
    # the trend averaged over the block's model points, from the trace's first point on
    sub = np.asarray(d.sub_time_s)
    trace = np.asarray(d.block_trace)
    start = sub[np.asarray(d.first_block), 0]
    expected = rates[trace] * (sub.mean(axis=1) - start[trace])
    np.testing.assert_allclose(diff, expected, rtol=0, atol=1e-9)
    # and at the blocks' own mean times, to within the model points' offset from the
    # block centre (half a sample, 0.5 ms here: the points are whole samples)
    half_sample_s = 0.5 * d.block_s / d.block_size
    at_block_time = rates[trace] * (np.asarray(d.block_time_s) - start[trace])
    atol = np.abs(rates).max() * half_sample_s + 1e-9
    np.testing.assert_allclose(diff, at_block_time, rtol=0, atol=atol)


@pytest.fixture(scope="module")
def drift_fit(drifting_bench):
    _, dataset, _ = drifting_bench
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return idtool.fit(dataset, seed=0, actuator="slope")


def test_the_fit_finds_the_drift_and_recovers_kt(drifting_bench, drift_fit):
    params, _, _ = drifting_bench
    ranking = drift_fit.run.ranking
    assert ranking[0][0] == "dahl/power-limited/slope/drift", drift_fit.run.reason
    assert ranking[1][1].bic - ranking[0][1].bic > 100.0  # not a near call
    kt = drift_fit.estimates["Kt"]
    true_kt = params.contact.contact_stiffness_n_m
    assert kt.ci95[0] <= true_kt <= kt.ci95[1], (kt, true_kt)
    mu = drift_fit.estimates["mu"]
    true_mu = params.contact.friction_coefficient
    assert abs(mu.estimate - true_mu) < 2.0 * (mu.ci95[1] - mu.ci95[0]), (mu, true_mu)


def test_every_trace_drift_rate_is_recovered(drifting_bench, drift_fit):
    _, _, truth = drifting_bench
    est = drift_fit.estimates
    for tr in truth.traces:
        e = est[f"offset_drift_n_s[{tr.id}]"]
        se = (e.ci95[1] - e.ci95[0]) / (2 * 1.96)
        # 4 standard errors: 24 traces, the AR(1) noise's se; a wrong sign or scale of
        # the model's time axis would miss by tens of them (the rates' sd is 0.3 N/s)
        assert abs(e.estimate - tr.offset_drift_n_s) < 4.0 * se + 1e-3, (tr.id, e, tr)


def test_fit_json_records_the_offset_model(drift_fit, tmp_path):
    drift_fit.save(tmp_path / "fit", plots=False)
    back = idtool.load_fit(tmp_path / "fit")
    assert back.model.offset is DriftingOffset
    assert back.model.names == drift_fit.model.names
    assert "drift load-cell offset" in back.report()
