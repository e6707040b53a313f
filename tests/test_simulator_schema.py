"""The simulator's parameter schema is made from the registries (idtool._simulate._schema):
the shipped file is that function's output, and a part registered later is simulated
through its typed record, its fields checked like the shipped parts'."""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

from idtool._data._blocks import prepare_fit_data
from idtool._data._example import example_params_path
from idtool._data._schema import SIMULATOR_PARAMS_SCHEMA, _schema_text
from idtool._data._write import json_bytes
from idtool._errors import IdtoolError
from idtool._model._coupling import COUPLINGS, GAIN, AbstractCoupling
from idtool._model._noise import NOISE_MODELS
from idtool._model._params import Param
from idtool._simulate import _records
from idtool._simulate._departures import departure_params
from idtool._simulate._params import BenchParams, load_bench_params
from idtool._simulate._records import coupling_laws, friction_laws
from idtool._simulate._schema import schema_text, simulator_params_schema
from idtool._simulate._simulate import simulate_bench


def test_the_schema_file_is_the_generated_schema():
    """Regenerate with ``python -m idtool._simulate._schema > datasets_schema/...``."""
    assert _schema_text(SIMULATOR_PARAMS_SCHEMA) == schema_text()


def test_every_registered_coupling_law_is_a_simulator_choice():
    schema = simulator_params_schema()
    choices = schema["properties"]["coupling"]["properties"]["law"]["enum"]
    assert {n.replace("-", "_") for n in COUPLINGS} < set(choices)
    assert {"load_exponential", "tanh_ceiling"} < set(choices)
    laws = schema["properties"]["contact"]["properties"]["friction_law"]["enum"]
    assert laws == ["coulomb", "dahl", "lugre"]
    noise = schema["properties"]["block_mean_noise"]["properties"]
    assert noise["model"]["enum"] == list(NOISE_MODELS)  # the registry's names, as registered
    assert {"sigma_n", "phi", "nu"} <= set(noise)
    assert "block_mean_noise" not in schema["required"]


def _example() -> dict:
    p = json.loads(example_params_path().read_text())
    p["experiments"].update(normal_loads_n=[450.0], amplitude_fractions=[0.5], repeats=1)
    p["experiments"]["on_durations_s"] = [1.0]
    return p


def test_a_wrong_field_for_the_law_is_located():
    p = _example()
    p["coupling"] = {"law": "exponential", "gain": 0.03, "power_load_n": 125.0}
    with pytest.raises(IdtoolError) as err:
        BenchParams.from_dict(p, "p.json")
    text = "\n".join(str(x) for x in err.value.problems)
    assert "coupling.saturation_load_n" in text and "missing required field" in text
    assert "remove field(s) power_load_n" in text
    p["coupling"] = {"law": "power_limited", "gain": -1.0, "power_load_n": 125.0}
    with pytest.raises(IdtoolError, match="invalid simulator parameters") as err:
        BenchParams.from_dict(p, "p.json")
    assert "coupling.gain" in str(err.value.problems[0]) and "must be > 0" in str(
        err.value.problems[0]
    )


class SquareRootCoupling(AbstractCoupling):
    """Toy: ``a = gain * sqrt(alpha) * A_max`` [m]."""

    gain: float
    fit_params: ClassVar[tuple[Param, ...]] = (GAIN,)

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        shape = jnp.broadcast_shapes(jnp.shape(amplitude_fraction), jnp.shape(normal_load_n))
        a = self.gain * jnp.sqrt(jnp.asarray(amplitude_fraction)) * max_amplitude_m
        return jnp.broadcast_to(a, shape)


def test_a_coupling_registered_later_is_simulated():
    COUPLINGS.register("square-root")(SquareRootCoupling)
    try:
        assert coupling_laws()["square_root"] is SquareRootCoupling
        p = _example()
        p["coupling"] = {"law": "square_root", "gain": 0.03}
        params = BenchParams.from_dict(copy.deepcopy(p))
        assert type(params.coupling).__name__ == "SquareRootCouplingParams"
        assert params.coupling.coupling(85e-6) == SquareRootCoupling(gain=0.03)
        _, truth = simulate_bench(params, seed=1)
        a = truth.operating_points[0].slip_amplitude_m
        assert a == pytest.approx(0.03 * 0.5**0.5 * 85e-6, rel=1e-12)
        assert BenchParams.from_dict(params.to_dict()) == params
    finally:
        COUPLINGS._entries.pop("square-root")


def _shrunk(params: BenchParams) -> BenchParams:
    """The first two loads and amplitudes, one repeat (a quick bench)."""
    e = params.experiments
    loads, amplitudes = e.normal_loads_n[:2], e.amplitude_fractions[:2]
    small = dataclasses.replace(e, repeats=1, normal_loads_n=loads, amplitude_fractions=amplitudes)
    return dataclasses.replace(params, experiments=small)


# sha256 of the datasets simulated (seed 7) before the simulator took its parts from the
# registries (main at 3be9e74): the records and the model's actuator change no byte.
# Pinned again after the slope actuator's OFF switch was rounded (issue 28, b094b07: the
# bench model, and so the simulator, changed there), from the simulator without the
# registries plus that change (branch lmconv, a6dae3d): the same three hashes as now.
# Pinned again when Parquet's zstd level went from 19 to 3 (2026-11-27: the bytes, not
# the arrays, changed; every array of the three benches, decoded, was equal bit for bit
# to the level-19 ones).
_BEFORE = {
    "example": "901b02d58bb1d781332cb0e3f01353e85c7772c6124ab5784b3205cfee27dd8e",
    "lag actuator": "9f5334cdf78016b738b2a934dfb35b7df7ce409baffa5b55c5370f08ed0b6319",
    "fading": "4ec2542bbb0cfa779523c11b092161bc2d0fb7d32363b7854b52a83bc46aaf8e",
}


@pytest.mark.parametrize("bench", list(_BEFORE))
def test_the_benches_are_those_simulated_before_the_registries(bench):
    if bench == "example":
        params = load_bench_params(example_params_path())
    else:
        kind = {"lag actuator": "actuator"}.get(bench, bench)
        params = _shrunk(departure_params(kind, 5))
    dataset, _ = simulate_bench(params, seed=7)
    assert dataset.sha256 == _BEFORE[bench]


def test_block_mean_noise_absent_changes_no_byte_and_present_moves_only_block_means():
    """Without ``block_mean_noise`` the example is the bench pinned above, bit for bit;
    with it, every trace differs from that bench by one constant per fit block (each
    block mean moves by its draw, nothing else moves) and the file round-trips."""
    params = load_bench_params(example_params_path())
    assert params.block_mean_noise is None and "block_mean_noise" not in params.to_dict()
    plain, _ = simulate_bench(params, seed=7)
    assert plain.sha256 == _BEFORE["example"]
    doc = params.to_dict() | {"block_mean_noise": {"model": "gaussian", "sigma_n": 0.2}}
    noisy, truth = simulate_bench(doc, seed=7)
    assert BenchParams.from_dict(doc).to_dict() == doc == truth.to_dict()["params"]
    data = prepare_fit_data(plain, mains_hz=50.0, periods_per_block=2)
    size = round(data.block_s * plain.traces[0].sample_rate_hz)
    drawn = []
    for before, after in zip(plain.traces, noisy.traces, strict=True):
        moved = np.asarray(after.force_n) - np.asarray(before.force_n)
        blocks = moved[: moved.size // size * size].reshape(-1, size)
        np.testing.assert_allclose(blocks, blocks[:, :1] + 0 * blocks, atol=1e-12)
        assert np.all(moved[blocks.size :] == 0.0)  # the tail past the last block
        drawn.extend(blocks[:, 0])
    # 0.2 N Gaussian, one draw per block (about 3600 here): the sd within 5%
    assert np.std(drawn) == pytest.approx(0.2, rel=0.05) and len(drawn) > 3000


def test_a_record_pickles_and_is_found_by_name():
    params = load_bench_params(example_params_path())
    assert pickle.loads(pickle.dumps(params)) == params
    # another process finds a record class by name before making it (module __getattr__)
    assert _records.LuGreParams.part.__name__ == "LuGre"
    with pytest.raises(AttributeError):
        _records.NoSuchParams  # noqa: B018


def test_every_registered_friction_law_is_simulated():
    values = {
        "friction_coefficient": 0.3,
        "contact_stiffness_n_m": 1e9,
        "static_ratio": 1.3,
        "stribeck_velocity_m_s": 0.01,
    }
    ratios = {}
    for name, law in friction_laws().items():
        p = _example()
        p["contact"] = {"friction_law": name} | {f.name: values[f.name] for f in law.truth_fields()}
        _, truth = simulate_bench(p, seed=1)
        json_bytes(truth.to_dict())  # the truth file, a rigid law's Lambda as null
        ratios[name] = truth.operating_points[0].friction_ratio
        assert (truth.operating_points[0].dimensionless_stiffness is None) == (name == "coulomb")
    # a static level above the kinetic one pulls the ON level up a little; the rigid
    # law's vibration reduces more than the compliant one's
    assert ratios["coulomb"] < ratios["dahl"] < ratios["lugre"] < 1.0
