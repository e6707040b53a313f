"""The public Python API: the documented names, no private imports in what users read,
the README's notebook-style script, and a coupling law added from outside the package."""

import importlib
import json
import re
from pathlib import Path
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import small_params

import idtool

ROOT = Path(__file__).parents[1]


def documented_names() -> list[str]:
    """The names listed between the README's ``api-names`` markers."""
    text = (ROOT / "README.md").read_text()
    block = text.split("<!-- api-names -->")[1].split("<!-- /api-names -->")[0]
    return re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", block)


def test_all_is_the_documented_list():
    assert sorted(idtool.__all__) == sorted(documented_names())
    for name in idtool.__all__:
        assert getattr(idtool, name) is not None, name


def test_readme_and_notebooks_use_public_names_only():
    for path in [ROOT / "README.md", *sorted((ROOT / "notebooks").glob("*.py"))]:
        hits = [line for line in path.read_text().splitlines() if "idtool._" in line]
        hits += [line for line in path.read_text().splitlines() if "from idtool import _" in line]
        assert hits == [], (path.name, hits)


@pytest.mark.slow
def test_readme_script_runs_with_public_names(readme_run):
    """The README's fit -> report -> sample -> predict -> amplitude script, as printed
    (run by the session's fixture, tests/conftest.py, in a folder of its own)."""
    scope, tmp_path = readme_run
    code = scope["__readme_code__"]
    assert len([line for line in code.splitlines() if line.strip()]) <= 12
    fit, pred, need = scope["fit"], scope["pred"], scope["need"]
    assert isinstance(fit, idtool.Fit) and fit.posterior is not None
    assert isinstance(pred, idtool.Predictions) and pred.source == "posterior"
    assert all(0.0 < p.ci95[0] < p.median < p.ci95[1] < 1.0 for p in pred)
    assert isinstance(need, idtool.Amplitudes) and len(need) >= 1
    # In memory and on disk agree: the saved fit reads back with the same estimates.
    back = idtool.load_fit(tmp_path / "fits" / "example")
    for name in fit.model.physical_names:
        assert back.estimates[name].estimate == pytest.approx(fit.estimates[name].estimate)


# ---------------------------------------------------------------------- a new coupling law
class LoadDecayCoupling(idtool.AbstractCoupling):
    """A toy law defined outside the package: ``a = gain alpha A_max / (1 + alpha N / P)``."""

    gain: float
    decay_load_n: float
    fit_params: ClassVar = (
        idtool.ConstantCoupling.fit_params[0],
        idtool.Param(
            "decay_load_n", "N", "log", 1.0, 1e5, physical=True, start=300.0,
            start_box=(20.0, 2000.0),
        ),
    )  # fmt: skip

    @classmethod
    def from_values(cls, values):
        return cls(gain=values["coupling_gain"], decay_load_n=values["decay_load_n"])

    def amplitude_m(self, amplitude_fraction, normal_load_n, max_amplitude_m):
        alpha = jnp.asarray(amplitude_fraction)
        return (
            self.gain * alpha * max_amplitude_m / (1.0 + alpha * normal_load_n / self.decay_load_n)
        )


@pytest.fixture(scope="module")
def load_decay():
    """Registered for this module only (the registry is global)."""
    idtool.COUPLINGS.register("test-load-decay")(LoadDecayCoupling)
    yield "test-load-decay"
    idtool.COUPLINGS._entries.pop("test-load-decay")


def test_a_coupling_law_is_one_class_plus_its_registration(load_decay, tmp_path):
    dataset, _ = idtool.simulate_bench(small_params(), seed=3)
    # one actuator and offset model, no levels model: the registry is what is tested (the
    # "auto" fit below then reuses these fits' compiled programs)
    one = {"actuator": "slope", "offset": "constant", "variability": False}
    fit = idtool.fit(dataset, coupling=load_decay, seed=0, **one)
    assert fit.model.coupling is LoadDecayCoupling
    assert fit.model.physical_names == ("Kt", "mu", "coupling_gain", "decay_load_n")
    est = fit.estimates
    assert all(np.isfinite(est[n].estimate) for n in fit.model.physical_names)
    # The data come from the power-limited law; a different saturating law still
    # passes through the measured operating points (both reproduce the traces' FR).
    ref = idtool.fit(dataset, coupling="power-limited", seed=0, **one)
    np.testing.assert_allclose(fit.result.friction_ratio, ref.result.friction_ratio, atol=0.01)
    # Names flow from the registry into fit.json, the report and the CLI's choices.
    doc = json.loads((fit.save(tmp_path / "fit", plots=False) / "fit.json").read_text())
    assert doc["coupling"] == load_decay and "decay_load_n" in doc["parameters"]
    assert f"{load_decay} coupling" in fit.report()
    from idtool._cli import build_parser

    fit_parser = build_parser()._subparsers._group_actions[0].choices["fit"]  # type: ignore[union-attr]
    coupling = next(a for a in fit_parser._actions if a.dest == "coupling")
    assert load_decay in coupling.choices
    # and "auto" fits it too, ranked by BIC with the shipped laws (one actuator and
    # offset model each, the levels model left out: the registry is what is tested)
    auto = idtool.fit(dataset, coupling="auto", seed=0, **one)
    assert f"dahl/{load_decay}/slope/constant" in auto.run.candidates
    # read back from disk: the law comes from the registry by its recorded name
    back = idtool.load_fit(tmp_path / "fit")
    assert back.model.coupling is LoadDecayCoupling


def test_unknown_names_are_refused_with_the_choices():
    dataset, _ = idtool.simulate_bench(small_params(), seed=3)
    with pytest.raises(idtool.IdtoolError, match=r"unknown coupling law 'bogus'.*constant"):
        idtool.fit(dataset, coupling="bogus")
    with pytest.raises(idtool.IdtoolError, match="unknown noise model"):
        idtool.fit(dataset, noise="pink")


def test_fit_predicts_in_memory_from_covariance_then_posterior():
    dataset, _ = idtool.simulate_bench(small_params(), seed=4)
    # one actuator and offset model (the data's): the predictions' source is what is
    # tested, not the choice among the candidate models
    fit = idtool.fit(dataset, seed=0, actuator="slope", offset="constant")
    before = fit.predict(450.0, [0.5, 0.7])
    assert before.source == "fit covariance" and len(before) == 2
    frame = before.to_frame()
    assert list(frame["normal_load_n"]) == [450.0, 450.0]
    assert {"friction_ratio.median", "friction_ratio.ci95.lo", "friction_ratio.ci95.hi"} <= set(
        frame.columns
    )
    assert (frame["friction_ratio.ci95.lo"] < frame["friction_ratio.median"]).all()
    far = fit.predict(900.0, 0.5)
    assert far.warnings and "outside the fitted range" in far.warnings[0]
    post = fit.sample(walkers=20, steps=200, seed=1)
    after = fit.predict(450.0, [0.5, 0.7])
    assert after.source == "posterior"
    same = post.predict(450.0, [0.5, 0.7])
    assert [p.median for p in same] == [p.median for p in after]
    idata = post.to_arviz()
    # the levels model's sds when the fit has them, else the noise model's parameters
    extra = {"scatter_mu", "discrepancy_fr"} if fit.levels is not None else {"sigma_n", "phi"}
    assert set(idata.posterior.data_vars) >= {"Kt", "mu"} | extra
    need = post.amplitude_for(40.0, [270.0, 670.0])
    assert [a.normal_load_n for a in need] == [270.0, 670.0]


def _type_checking_block(lazy: dict[str, str]) -> str:
    """The TYPE_CHECKING block of idtool/__init__.py for the lazy table ``lazy``."""
    by_module: dict[str, list[str]] = {}
    for name, module in lazy.items():
        by_module.setdefault(module, []).append(name)
    lines = ["if TYPE_CHECKING:"]
    for module in sorted(by_module):
        lines.append(f"    from {module} import (")
        lines += [f"        {n} as {n}," for n in sorted(by_module[module], key=str.lower)]
        lines.append("    )")
    return "\n".join(lines)


def test_the_type_checking_imports_are_the_lazy_table():
    """One list of public names (``idtool._LAZY``): the eager imports type checkers read
    name the same objects from the same modules, each re-exported as itself."""
    import ast

    tree = ast.parse((ROOT / "idtool" / "__init__.py").read_text())
    (block,) = [
        node
        for node in tree.body
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
    ]
    imported = {
        alias.name: (node.module, alias.asname)
        for node in block.body
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    }
    expected = {name: (module, name) for name, module in idtool._LAZY.items()}
    assert imported == expected, "paste into idtool/__init__.py:\n" + _type_checking_block(
        idtool._LAZY
    )
    for name, module in idtool._LAZY.items():  # each module defines what it is said to
        assert hasattr(importlib.import_module(module), name), (module, name)


def test_every_public_name_resolves_lazily():
    """``__all__`` and the lazy table agree, and ``import idtool`` loads none of the
    heavy modules a command may not need."""
    import subprocess
    import sys

    assert set(idtool.__all__) == {*idtool._LAZY, "__version__"}
    code = (
        "import sys, idtool; "
        "print(sorted({m.split('.')[0] for m in sys.modules} & "
        "{'equinox', 'pandas', 'matplotlib', 'arviz', 'emcee', 'scipy', 'pyarrow'}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert "Fit" in dir(idtool)
