"""A part defined outside the package is one class plus its registration, for the fit
AND the simulator: a toy coupling law registered here is simulated (its parameters in
the simulator's file, checked by the schema the registries make) and fitted back, its
true parameters inside their 95% intervals."""

from __future__ import annotations

import json
from typing import ClassVar

import jax.numpy as jnp
import pytest

import idtool
from idtool._simulate._schema import simulator_params_schema

TRUE_GAIN, TRUE_KNEE_N = 0.03, 250.0


class KneeCoupling(idtool.AbstractCoupling):
    """Toy: ``a = gain alpha A_max / (1 + (alpha N / P)^4)^(1/4)``, a sharper knee than
    the power limit's."""

    gain: float
    knee_load_n: float
    fit_params: ClassVar = (
        idtool.ConstantCoupling.fit_params[0],
        idtool.Param(
            "knee_load_n", "N", "log", 1.0, 1e5, physical=True, start=300.0,
            start_box=(20.0, 2000.0), description="load scale P of the knee",
        ),
    )  # fmt: skip

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"], knee_load_n=values["knee_load_n"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        x = alpha * jnp.asarray(normal_load_n) / self.knee_load_n
        return self.gain * alpha * max_amplitude_m / (1.0 + x**4) ** 0.25


@pytest.fixture(scope="module")
def knee():
    """Registered for this module only (the registry is global)."""
    idtool.COUPLINGS.register("test-knee")(KneeCoupling)
    yield "test-knee"
    idtool.COUPLINGS._entries.pop("test-knee")


def _params() -> dict:
    p = json.loads(idtool.example_params_path().read_text())
    p["experiments"].update(amplitude_fractions=[0.3, 0.7], on_durations_s=[1.0, 2.5], repeats=1)
    p["coupling"] = {"law": "test_knee", "gain": TRUE_GAIN, "knee_load_n": TRUE_KNEE_N}
    return p


def test_a_toy_coupling_law_is_simulated_and_fitted_back(knee):
    schema = simulator_params_schema()["properties"]["coupling"]
    assert "test_knee" in schema["properties"]["law"]["enum"]
    assert schema["properties"]["knee_load_n"]["description"] == "Load scale P of the knee [N]."
    dataset, truth = idtool.simulate_bench(_params(), seed=11)
    assert truth.params.coupling.in_fit
    assert truth.to_dict()["coupling"] == _params()["coupling"]
    fit = idtool.fit(dataset, coupling=knee, seed=0)
    assert fit.model.coupling is KneeCoupling
    true = {
        "coupling_gain": TRUE_GAIN,
        "knee_load_n": TRUE_KNEE_N,
        "mu": truth.params.contact.friction_coefficient,
        "Kt": truth.params.contact.contact_stiffness_n_m,
    }
    for name, value in true.items():
        lo, hi = fit.estimates[name].ci95
        assert lo <= value <= hi, (name, value, (lo, hi))
    # a wrong field for the toy law is refused where it is, like a shipped law's
    bad = _params()
    bad["coupling"]["power_load_n"] = 125.0
    with pytest.raises(idtool.IdtoolError) as err:
        idtool.simulate_bench(bad, seed=11)
    assert "remove field(s) power_load_n" in "\n".join(str(p) for p in err.value.problems)
