"""One fit artefact (issue 27, item 1): a fit just made and the same fit read back from its
folder are the same object and behave identically, every public method giving equal
results; the fit folder is declared once and documented; fit.json has a versioned JSON
Schema, and a fit.json written before the version reads as version 1."""

import dataclasses
import importlib
import json
import re
import shutil
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import pytest
from sample_helpers import small_params

import idtool
from idtool._data._schema import schema_validator
from idtool._diagnostic import Diagnostic
from idtool._fit._folder import FIT_FOLDER, FIT_JSON, FIT_SCHEMA_VERSION

ROOT = Path(__file__).parents[1]


def same(a, b, where: str = "") -> None:
    """``a`` and ``b`` equal all the way down: arrays element by element (NaN equal to
    NaN), dataclasses and equinox modules field by field, diagnostics with their codes
    and values."""
    if isinstance(a, eqx.Module):
        leaves_a, tree_a = jax.tree_util.tree_flatten(a)
        leaves_b, tree_b = jax.tree_util.tree_flatten(b)
        assert tree_a == tree_b, where
        for i, (x, y) in enumerate(zip(leaves_a, leaves_b, strict=True)):
            same(x, y, f"{where}.leaf{i}")
    elif dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, Diagnostic):
        assert isinstance(b, Diagnostic), where
        assert (str(a), a.code, a.severity) == (str(b), b.code, b.severity), where
        same(a.values, b.values, where)
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, list | tuple):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray | jax.Array | np.generic | float):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)
    else:
        assert a == b, where


@pytest.fixture(scope="module")
def fresh_and_loaded(tmp_path_factory):
    """A fit of every coupling law (the other laws kept for averaging) with the levels
    model, saved, and read back."""
    root = tmp_path_factory.mktemp("artefact")
    dataset, _ = idtool.simulate_bench(small_params(), seed=5)
    data = idtool.load_dataset(idtool.write_dataset(dataset, root / "data"))
    fresh = idtool.fit(data, coupling="auto", actuator="slope", offset="constant", seed=0)
    fresh.save(root / "fit")
    loaded = idtool.load_fit(root / "fit")
    other, _ = idtool.simulate_bench(small_params(), seed=6)
    return fresh, loaded, other, root


# Every public attribute of Fit, and how to ask it: a new one fails
# test_every_public_method_is_compared until it is added here.
CALLS = {
    "dataset": lambda f, other, root: f.dataset,
    "model": lambda f, other, root: f.model,
    "z": lambda f, other, root: f.z,
    "cov_z": lambda f, other, root: f.cov_z,
    "phi": lambda f, other, root: f.phi,
    "noise_state": lambda f, other, root: f.noise_state,
    "sigma_n": lambda f, other, root: f.sigma_n,
    "seconds": lambda f, other, root: f.seconds,
    "levels": lambda f, other, root: f.levels,
    "conditioning": lambda f, other, root: f.conditioning,
    "estimates": lambda f, other, root: f.estimates,
    "optima": lambda f, other, root: f.optima,
    "warnings": lambda f, other, root: f.warnings,
    "notes": lambda f, other, root: f.notes,
    "coupling_laws": lambda f, other, root: f.coupling_laws,
    "directions": lambda f, other, root: f.directions,
    "artefact": lambda f, other, root: f.artefact,
    "report": lambda f, other, root: f.report(),
    "draws": lambda f, other, root: f.draws(300, seed=2),
    "predict": lambda f, other, root: f.predict([270.0, 500.0], [0.5, 0.7], max_draws=300),
    "amplitude_for": lambda f, other, root: f.amplitude_for(30.0, 450.0, max_draws=300),
    "validate": lambda f, other, root: f.validate(other, max_draws=300),
    "to_json": lambda f, other, root: f.to_json(),
    "save": lambda f, other, root: _saved(f, root),
    "plan": lambda f, other, root: f.plan(
        "band", 2, at=[(450.0, 0.6)], grid=(3, 3), max_draws=200, seed=1
    ),
}
# the run and its chosen result (the candidates in memory) are a fresh fit's only, and
# from_run makes one
IN_MEMORY = {"run", "result", "from_run"}
# compared in test_a_posterior_sampled_from_either_is_the_same (a chain each)
SAMPLING = {"sample", "save_posterior", "posterior", "folder"}


def _saved(fit, root: Path) -> dict:
    """The folder ``fit.save`` writes, file by file (arrays for the state files)."""
    out = fit.save(root / f"again-{id(fit)}", plots=False)
    files = {}
    for path in sorted(out.iterdir()):
        if path.suffix == ".npz":
            with np.load(path) as npz:
                files[path.name] = {k: np.asarray(npz[k]) for k in npz.files}
        else:
            files[path.name] = path.read_text()
    shutil.rmtree(out)
    return files


def test_every_public_method_is_compared():
    public = {n for n in dir(idtool.Fit) if not n.startswith("_")}
    public |= {"dataset", "artefact", "run", "folder", "posterior"}  # set in __init__
    assert public == set(CALLS) | IN_MEMORY | SAMPLING


@pytest.mark.parametrize("name", sorted(CALLS))
def test_a_fresh_and_a_loaded_fit_give_equal_results(fresh_and_loaded, name):
    fresh, loaded, other, root = fresh_and_loaded
    same(CALLS[name](fresh, other, root), CALLS[name](loaded, other, root), name)


def test_the_fit_keeps_other_laws_and_says_so(fresh_and_loaded):
    """The fixture exercises what the stored fit used to lose: the other coupling laws
    (averaged over), the levels model, the diagnostics' codes, the optima."""
    fresh, loaded, _, _ = fresh_and_loaded
    assert loaded.artefact.alternates, "no coupling law kept besides the chosen one"
    assert loaded.levels is not None and len(loaded.optima) >= 1
    assert loaded.draws(300).law_weights.keys() == loaded.coupling_laws.keys() & {
        loaded.model.coupling.name,
        *loaded.artefact.alternates,
    }
    assert loaded.artefact.schema_version == FIT_SCHEMA_VERSION
    assert loaded.artefact.spec.key in [m["model"] for m in loaded.to_json()["model_comparison"]]
    with pytest.raises(idtool.IdtoolError, match="not its result"):
        _ = loaded.result
    assert fresh.result.model.names == loaded.model.names


def test_a_posterior_sampled_from_either_is_the_same(fresh_and_loaded, tmp_path):
    """The same seed gives the same chain from the fresh fit and the loaded one, and the
    posterior predicts as its fit does: averaged over the same coupling laws."""
    fresh, loaded, _, _ = fresh_and_loaded
    try:
        posts = [f.sample(walkers=16, steps=30, seed=3) for f in (fresh, loaded)]
        np.testing.assert_array_equal(posts[0].chain, posts[1].chain)
        for f, post in zip((fresh, loaded), posts, strict=True):
            from_fit = f.predict(450.0, 0.5, max_draws=200)
            from_post = post.predict(450.0, 0.5, max_draws=200)
            same(from_fit.to_dict(), from_post.to_dict())
            assert from_post.source == "posterior" and from_post[0].by_law
            # the seed reaches the posterior's own path too (the sds' draws)
            seeded = post.predict(450.0, 0.5, max_draws=200, seed=7)
            same(f.predict(450.0, 0.5, max_draws=200, seed=7).to_dict(), seeded.to_dict())
            assert seeded.to_dict() != from_post.to_dict()  # the seed matters here
        same(fresh.predict(450.0, 0.5).to_dict(), loaded.predict(450.0, 0.5).to_dict())
        texts = []
        for f, name in ((fresh, "a"), (loaded, "b")):
            (tmp_path / name).mkdir()  # the report names its folder
            texts.append(f.save_posterior(tmp_path / name).replace(str(tmp_path / name), "F"))
        # equal but for the folder's name and the times taken (compiling, sampling)
        assert [re.sub(r"\d+\.\d+ s\b", "T s", t) for t in texts[0:1]] == [
            re.sub(r"\d+\.\d+ s\b", "T s", t) for t in texts[1:2]
        ]
    finally:  # the fixture's fits are shared: leave them without a posterior
        for f in (fresh, loaded):
            f.posterior = None


def test_a_sampled_fit_predicts_the_same_through_every_public_path(fresh_and_loaded, tmp_path):
    """After ``Fit.sample``: ``Fit.predict``, the returned ``Posterior``'s ``predict``
    and the fit read back with its ``posterior.nc`` (``load_fit``) take the same draws
    (those ``posterior.nc`` keeps) and average the same coupling laws by the same
    weights, so their predictions and amplitudes are equal. Before the in-memory chain
    and the stored one were one draws path, the fit read back predicted from the
    thinned, walker-major draws of the file and the one in memory from every kept draw
    step by step: the same law weights, other bands (FR's 95% lower bound at 450 N, 50%:
    0.2261 read back against 0.2279 in memory, 2000 draws)."""
    fresh, _, _, root = fresh_and_loaded
    folder = shutil.copytree(root / "fit", tmp_path / "fit")  # the fixture's is read-only
    try:
        post = fresh.sample(walkers=16, steps=30, seed=3)
        fresh.save_posterior(folder)
        back = idtool.load_fit(folder)
        assert back.posterior is None  # read back, its draws come from posterior.nc
        for max_draws in (200, 2000):  # a subset of the 416 kept draws, and all of them
            preds = [
                p.predict([270.0, 450.0], [0.5, 0.7], max_draws=max_draws)
                for p in (fresh, post, back)
            ]
            assert preds[0].to_dict()["rows"] == preds[1].to_dict()["rows"]
            assert preds[0].to_dict()["rows"] == preds[2].to_dict()["rows"]
            assert all(p.source == "posterior" and len(p[0].by_law) > 1 for p in preds)
        amps = [p.amplitude_for(60.0, 450.0, max_draws=300) for p in (fresh, post, back)]
        assert amps[0].to_dict()["rows"] == amps[1].to_dict()["rows"] == amps[2].to_dict()["rows"]
        weights = fresh.draws(300).law_weights
        assert len(weights) > 1 and back.draws(300).law_weights == weights
    finally:  # the fixture's fits are shared: leave them without a posterior
        fresh.posterior = None


def test_fit_json_is_valid_against_its_schema(fresh_and_loaded):
    root = fresh_and_loaded[3]
    doc = json.loads((root / "fit" / FIT_JSON.name).read_text())
    assert doc["schema_version"] == FIT_SCHEMA_VERSION == FIT_JSON.schema_version
    errors = list(schema_validator(FIT_JSON.schema).iter_errors(doc))
    assert errors == []
    broken = dict(doc, parameters={"Kt": {"estimate": "high"}})
    assert list(schema_validator(FIT_JSON.schema).iter_errors(broken))


def test_a_fit_folder_before_the_schema_version_reads_as_version_1(fresh_and_loaded, tmp_path):
    """fit.json without ``schema_version`` and fit_state.npz without the optima (as
    written before both): the same fit, its optima taken from fit.json's physical values."""
    _, loaded, _, root = fresh_and_loaded
    old = shutil.copytree(root / "fit", tmp_path / "old")
    doc = json.loads((old / FIT_JSON.name).read_text())
    del doc["schema_version"]
    (old / FIT_JSON.name).write_text(json.dumps(doc))
    with np.load(old / "fit_state.npz") as npz:
        arrays = {k: npz[k] for k in npz.files if not k.startswith("optima_")}
    np.savez(old / "fit_state.npz", **arrays)
    back = idtool.load_fit(old)
    assert back.artefact.schema_version == "1"
    same(back.estimates, loaded.estimates)
    same(back.draws(200).values, loaded.draws(200).values)
    for a, b in zip(back.optima, loaded.optima, strict=True):
        # z -> value -> z goes through u = 1 / (1 + e^-z) and back through log(u / (1 - u)):
        # 1 - u carries float64's absolute rounding (2.2e-16), i.e. a relative error of
        # 2.2e-16 (1 + e^|z|) that the logit passes to z. A parameter at the end of its
        # range (Kt here: z = 21.3, e^z = 1.7e9) reads back to ~4e-7, one inside to ~1e-15.
        bound = 4 * np.finfo(float).eps * (1.0 + np.exp(np.abs(b["z"])))
        assert np.all(np.abs(a["z"] - b["z"]) <= bound + 1e-12), (a["z"], b["z"], bound)
    doc["schema_version"] = "99"
    (old / FIT_JSON.name).write_text(json.dumps(doc))
    with pytest.raises(idtool.IdtoolError, match=r"fit\.json: schema version 99.*update idtool"):
        idtool.load_fit(old)


def test_the_fit_folder_is_declared_once_and_documented():
    """Every declared file is in docs/outputs.md's table, and the table names no file the
    declaration lacks; every declared schema is published."""
    text = (ROOT / "docs" / "outputs.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    documented = {name for row in rows for name in re.findall(r"`([^`]+)`", row.split("|")[1])}
    declared = {f.name.replace("{law}", "LAW") for f in FIT_FOLDER}
    assert declared <= documented
    assert {n for n in documented - declared if "." in n} <= {
        "compare.html",
        "compare.json",
        "true_parameters.json",
    }
    for f in FIT_FOLDER:
        if f.schema is not None:
            assert (ROOT / "datasets_schema" / f.schema).is_file()
        for where in filter(None, (f.writer, f.reader)):  # each names a real function
            module, name = where.split(":")
            assert callable(getattr(importlib.import_module(module), name)), where


def test_a_fit_folder_with_dense_covariances_reads_and_predicts_the_same(
    fresh_and_loaded, tmp_path
):
    """The state files hold the covariances of ``z`` and of the free levels in blocks,
    nothing of size (p, p) or (levels, levels) (issue 28); a folder written before the
    blocks (``cov_z`` and ``levels_cov_y`` dense, as each law's state file held them)
    reads to the same matrices and predicts the same. Such a folder also predates the
    levels model's Jacobian (version 3): compared with the same folder in blocks without
    it, both drawing at the REML sds' covariance."""
    _, _, _, root = fresh_and_loaded
    old = shutil.copytree(root / "fit", tmp_path / "old")
    blocked = shutil.copytree(root / "fit", tmp_path / "blocked")
    for path in sorted(blocked.glob("fit_state*.npz")):
        with np.load(path) as npz:
            np.savez(path, **{k: np.asarray(npz[k]) for k in npz.files if k != "levels_jacobian"})
    loaded = idtool.load_fit(blocked)
    blocks = ("cov_z_shared", "cov_z_cross", "cov_z_block", "cov_z_load", "cov_z_core")
    fit = idtool.load_fit(root / "fit")
    laws = [fit.artefact.chosen] + [law for _, law in fit.artefact.alternates.values()]
    files = sorted(old.glob("fit_state*.npz"))
    assert len(files) == len(laws) > 1
    for path in files:
        with np.load(path) as npz:
            arrays = {k: np.asarray(npz[k]) for k in npz.files}
        p, n = arrays["z"].size, arrays["levels_y"].size
        assert set(blocks) <= set(arrays) and "cov_z" not in arrays
        assert "levels_cov_block" in arrays and "levels_cov_y" not in arrays
        assert all(a.shape not in ((p, p), (n, n)) for a in arrays.values()), path.name
        law = next(w for w in laws if np.array_equal(w.z, arrays["z"]))
        dense = {
            k: a
            for k, a in arrays.items()
            if k not in blocks and "levels_cov_" not in k and k != "levels_jacobian"
        }
        dense["cov_z"] = law.cov_z.dense()
        dense["levels_cov_y"] = law.levels[0].covariance()
        np.savez(path, **dense)
    back = idtool.load_fit(old)
    assert back.levels[0].cov_parts is None and back.levels[0].cov_y is not None
    np.testing.assert_array_equal(back.cov_z.dense(), loaded.cov_z.dense())
    np.testing.assert_array_equal(back.levels[0].covariance(), loaded.levels[0].covariance())
    np.testing.assert_allclose(
        back.levels[0].variances(), loaded.levels[0].variances(), rtol=1e-12, atol=0
    )
    same(back.draws(300, seed=2).values, loaded.draws(300, seed=2).values)
    a = back.predict([270.0, 500.0], [0.5, 0.7], max_draws=300)
    b = loaded.predict([270.0, 500.0], [0.5, 0.7], max_draws=300)
    for x, y in zip(a, b, strict=True):
        # the conditioning's FR covariance: the dense matrix's block, or the same from
        # the blocks (one rounding of a dot product apart)
        np.testing.assert_allclose(x.median, y.median, rtol=1e-10)
        np.testing.assert_allclose(x.ci95, y.ci95, rtol=1e-10)
        assert x.new_trace is not None and y.new_trace is not None
        np.testing.assert_allclose(x.new_trace[1], y.new_trace[1], rtol=1e-10)
