"""A noise model defined outside the package is one class plus its registration: a toy
AR(2) model of the block means, registered here, is named in a simulator parameter file
(its ``block_mean_noise``, written here and simulated by ``idtool simulate-bench``:
block-mean noise drawn from it on the fit's blocks, idtool._simulate._block_noise) and
fitted back. AR(1), the default, cannot see its lag-2 correlation; the toy's fit can,
through the interface alone (AbstractNoise: the state, whitening, its inverse, its
estimate, its log-determinant)."""

from __future__ import annotations

import json
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import idtool
from idtool._cli._main import main
from idtool._fit._program import prediction_at
from idtool._model._noise import AR1Noise
from idtool._simulate._schema import simulator_params_schema
from idtool._simulate._simulate import TRUTH_FILE

TRUE_A1, TRUE_A2, TRUE_SIGMA_N = 0.3, 0.4, 0.5
A1 = idtool.Param("ar2_a1", "1", "tanh", -2.0, 2.0, description="AR(2) lag-1 coefficient")
A2 = idtool.Param("ar2_a2", "1", "tanh", -1.0, 1.0, description="AR(2) lag-2 coefficient")


def _ar2_scales(a1, a2, xp):
    """The exact whitening's scales of a trace's first two blocks and ``rho_1``: the
    stationary sd of ``e`` is ``sigma / c0``; ``e_1`` given ``e_0`` has mean
    ``rho_1 e_0`` and sd ``sigma / c1`` (Box & Jenkins, AR(2) autocovariances)."""
    c0 = xp.sqrt((1.0 + a2) * ((1.0 - a2) ** 2 - a1**2) / (1.0 - a2))
    return c0, xp.sqrt(1.0 - a2**2), a1 / (1.0 - a2)


class AR2Noise(idtool.AbstractNoise):
    """Toy: Gaussian ``e_t = a1 e_{t-1} + a2 e_{t-2} + sigma eps_t`` within each trace,
    stationary start; state ``[a1, a2]``."""

    params: ClassVar = (idtool.AbstractNoise.params[0], A1, A2)
    state_params: ClassVar = (A1, A2)
    description: ClassVar[str] = "Gaussian AR(2) within each trace (test)"

    def whiten(self, e, first, state):
        a1, a2 = state[0], state[1]
        c0, c1, rho1 = _ar2_scales(a1, a2, jnp)
        shape = (-1,) + (1,) * (e.ndim - 1)
        at_first = jnp.asarray(first).reshape(shape)
        at_second = jnp.roll(jnp.asarray(first), 1).reshape(shape)
        e1, e2 = jnp.roll(e, 1, axis=0), jnp.roll(e, 2, axis=0)
        inner = e - a1 * e1 - a2 * e2
        return jnp.where(at_first, c0 * e, jnp.where(at_second, c1 * (e - rho1 * e1), inner))

    def unwhiten(self, w, first, state):
        a1, a2 = (np.asarray(s, float) for s in np.asarray(state, float))
        c0, c1, rho1 = _ar2_scales(a1, a2, np)
        w = np.asarray(w, float)
        e = np.array(w)
        for t in range(e.shape[-1]):
            if first[t]:
                e[..., t] = w[..., t] / c0
            elif first[t - 1]:
                e[..., t] = w[..., t] / c1 + rho1 * e[..., t - 1]
            else:
                e[..., t] = w[..., t] + a1 * e[..., t - 1] + a2 * e[..., t - 2]
        return e

    def estimate_state(self, e, first):
        r1, r2 = _autocorrelations(e, first, 2)
        a1 = r1 * (1.0 - r2) / (1.0 - r1**2)  # Yule-Walker
        a2 = (r2 - r1**2) / (1.0 - r1**2)
        return np.clip(np.array([a1, a2]), -0.95, 0.95)

    def trace_log_det(self, state):
        c0, c1, _ = _ar2_scales(state[0], state[1], jnp)
        return jnp.log(c0) + jnp.log(c1)


def _autocorrelations(e, first, lags: int) -> list[float]:
    """Pooled within-trace autocorrelations of ``e`` at lags 1..``lags``."""
    e, first = np.asarray(e, float), np.asarray(first, bool)
    trace = np.cumsum(first)
    return [
        float(np.sum((e[k:] * e[:-k])[trace[k:] == trace[:-k]]) / np.sum(e**2))
        for k in range(1, lags + 1)
    ]


@pytest.fixture(scope="module")
def ar2():
    """Registered for this module only (the registry is global)."""
    idtool.NOISE_MODELS.register("test-ar2")(AR2Noise)
    yield "test-ar2"
    idtool.NOISE_MODELS._entries.pop("test-ar2")


def _params(noise: dict) -> dict:
    """The example's design, its sample-rate load-cell noise off, ``noise`` as its
    block-mean noise."""
    p = json.loads(idtool.example_params_path().read_text())
    p["load_cell"].update(white_noise_std_n=0.0, correlated_noise_std_n=0.0)
    return p | {"block_mean_noise": noise}


@pytest.fixture(scope="module")
def dataset(ar2, tmp_path_factory):
    """AR(2) block means from a parameter file naming the toy, by the command line."""
    root = tmp_path_factory.mktemp("toy-noise")
    noise = {"model": ar2, "sigma_n": TRUE_SIGMA_N, "ar2_a1": TRUE_A1, "ar2_a2": TRUE_A2}
    (root / "p.json").write_text(json.dumps(_params(noise)))
    args = ["simulate-bench", "--params", str(root / "p.json"), "--out", str(root / "sim")]
    assert main([*args, "--seed", "7"]) == 0
    truth = json.loads((root / "sim" / TRUTH_FILE).read_text())
    assert truth["params"]["block_mean_noise"] == noise
    return idtool.load_dataset(root / "sim")


def _fit(dataset, noise):
    return idtool.fit(
        dataset, noise=noise, coupling="power-limited", actuator="slope", offset="constant"
    )


def _whitened_autocorrelations(fit) -> list[float]:
    _, w = prediction_at(fit.model, fit.z, fit.noise_state)
    return _autocorrelations(w, fit.model.data.first, 2)


@pytest.mark.slow
def test_a_toy_ar2_noise_model_is_simulated_and_fitted_back(ar2, dataset):
    toy = _fit(dataset, ar2)
    assert type(toy.model.noise) is AR2Noise
    a1, a2 = toy.noise_state
    assert abs(a1 - TRUE_A1) < 0.06 and abs(a2 - TRUE_A2) < 0.06, (a1, a2)
    toy_r1, toy_r2 = _whitened_autocorrelations(toy)
    assert abs(toy_r1) < 0.05 and abs(toy_r2) < 0.05, (toy_r1, toy_r2)
    assert toy.sigma_n == pytest.approx(TRUE_SIGMA_N, rel=0.05)
    noise = toy.to_json()["noise"]
    assert noise["parameters"] == {"ar2_a1": a1, "ar2_a2": a2} and noise["phi"] == 0.0

    ar1 = _fit(dataset, "ar1")
    r1, r2 = _whitened_autocorrelations(ar1)
    # AR(1) leaves lag 2 in its whitened residuals (0.36 measured; the toy's 0.01)
    assert r2 > 0.2, (r1, r2)
    assert ar1.to_json()["noise"]["parameters"] == {"phi": ar1.phi}
    # the exact likelihoods (log-determinants included) prefer the true model
    assert toy.result.loglik > ar1.result.loglik + 50.0


def test_the_toy_is_a_choice_of_the_parameter_file_and_checked_there(ar2, tmp_path, capsys):
    """The schema made now lists the toy and its own parameters with their ranges; the
    file's bad name, missing parameter and non-stationary parameters are located
    errors (exit status 2 from the command line), not tracebacks."""
    section = simulator_params_schema()["properties"]["block_mean_noise"]
    assert ar2 in section["properties"]["model"]["enum"]
    assert section["properties"]["ar2_a2"]["exclusiveMaximum"] == 1.0
    assert "AR(2) lag-1 coefficient [-]" in section["properties"]["ar2_a1"]["description"]
    good = {"model": ar2, "sigma_n": 0.5, "ar2_a1": 0.3, "ar2_a2": 0.4}
    record = idtool.BenchParams.from_dict(_params(good)).block_mean_noise
    assert record is not None and record.values() == {k: good[k] for k in good if k != "model"}
    assert type(record.noise()) is AR2Noise
    bad = {
        "ar3": ({"model": "ar3", "sigma_n": 0.5}, "block_mean_noise.model", "test-ar2"),
        "missing": (
            {"model": ar2, "sigma_n": 0.5, "ar2_a1": 0.3},
            "block_mean_noise.ar2_a2",
            "missing required field",
        ),
        # inside each coefficient's range, outside the stationary triangle: c0^2 < 0
        "explosive": (
            {"model": ar2, "sigma_n": 0.5, "ar2_a1": 1.5, "ar2_a2": 0.6},
            "block_mean_noise",
            "stationary",
        ),
    }
    for name, (noise, column, words) in bad.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(_params(noise)))
        assert main(["simulate-bench", "--params", str(path), "--out", str(tmp_path / name)]) == 2
        err = capsys.readouterr().err
        assert f"{path}, column '{column}'" in err and words in err, (name, err)
        assert not (tmp_path / name).exists()


def test_the_generic_nuisance_equations_match_ar1s_gram():
    """AbstractNoise's nuisance equations (the Jacobian whitened per walker) against
    AR(1)'s own (a Gram quadratic in phi): the path a new correlated model takes."""

    class PlainAR1(idtool.AbstractNoise):  # AR(1)'s whitening, the default equations
        state_params: ClassVar = AR1Noise.state_params

        def whiten(self, e, first, state):
            return AR1Noise().whiten(e, first, state)

    rng = np.random.default_rng(0)
    first = np.zeros(30, bool)
    first[[0, 12, 19]] = True
    block_trace = np.cumsum(first) - 1
    continues = np.append(~first[1:], False)
    jac, w = rng.standard_normal((30, 4)), rng.standard_normal((30, 5))
    state = jnp.asarray(rng.uniform(-0.9, 0.9, (1, 5)))
    args = (jnp.asarray(first), jnp.asarray(continues), jnp.asarray(block_trace), state)
    got = []
    for noise in (AR1Noise(), PlainAR1()):
        gram = jnp.asarray(noise.gram_terms(jac, first, block_trace, 3))
        got.append(noise.nuisance_equations(jnp.asarray(w), jnp.asarray(jac), gram, *args))
    for mine, ar1 in zip(got[1], got[0], strict=True):
        np.testing.assert_allclose(mine, ar1, rtol=1e-12, atol=1e-12)
