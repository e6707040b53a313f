"""The fit's covariance in arrowhead blocks (issue 28, memory linear in the traces): the
blocks are the dense pseudo-inverse of the normal equations, every operation the
readers use gives what the dense matrix gave, no state file holds a (p, p) array, and a
fit folder written before the blocks (a dense ``cov_z``) loads and predicts as it did."""

import dataclasses
import shutil

import numpy as np
import pytest
from sample_helpers import random_arrow, small_fit

import idtool
from idtool._fit import _program
from idtool._fit._arrow import block_index, inverse_and_weakest
from idtool._fit._cov import STATE_KEYS, ArrowCovariance, DenseCovariance
from idtool._fit._folder import FIT_STATE
from idtool._fit._intervals import profile_start
from idtool._posterior._likelihood import conditioning_shrinkage
from idtool._predict._predict import draws_from_covariance

REL = 1e-10


def close(got, ref, where: str = "") -> None:
    """Equal to ``REL`` of the reference's largest entry."""
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    scale = max(float(np.max(np.abs(ref))), 1e-300)
    np.testing.assert_allclose(got, ref, rtol=0, atol=REL * scale, err_msg=where)


def check_every_operation(blocks: ArrowCovariance, seed: int = 0) -> None:
    """Each operation on the blocks against the same on their dense matrix
    (:class:`DenseCovariance`: the expressions the readers used on ``cov_z``)."""
    dense = DenseCovariance(blocks.dense(), blocks.n_shared)
    p, s = dense.size, blocks.n_shared
    assert blocks.size == p
    close(blocks.diagonal(), dense.diagonal(), "diagonal")
    for k in (1, s):
        close(blocks.leading(k), dense.leading(k), f"leading({k})")
    with pytest.raises(ValueError):
        blocks.leading(s + 1)
    for i in range(p):
        close(blocks.column(i), dense.column(i), f"column({i})")
    rng = np.random.default_rng(seed)
    for _ in range(5):
        g = rng.standard_normal(p)
        bound = REL * float(g @ g) * np.abs(dense.matrix).max()
        assert blocks.quad(g) == pytest.approx(dense.quad(g), rel=REL, abs=bound)
    close(blocks.scaled(2.5).dense(), dense.scaled(2.5).dense(), "scaled")
    k = min(2, s)
    theta = np.array([[2.0, 0.3], [0.3, 1.0]])[:k, :k]
    edited = blocks.with_leading(k, theta)
    close(edited.dense(), dense.with_leading(k, theta).dense(), "with_leading")
    close(edited.shared_given_nuisances(), dense.with_leading(k, theta).shared_given_nuisances())
    close(blocks.shared_given_nuisances(), dense.shared_given_nuisances(), "given nuisances")


@pytest.mark.parametrize("singular", [False, True])
def test_the_blocks_are_the_dense_pseudo_inverse(singular):
    """(a) a random well-conditioned arrowhead; (b) one with a zero column (a nuisance the
    data do not move): the pseudo-inverse's semantics, zero variance there."""
    arrow = random_arrow(zero=(2, 1)) if singular else random_arrow(1, s=4, m=7, nb=3, rows=20)
    blocks, ratio, _ = inverse_and_weakest(arrow, arrow.a.shape[0])
    assert isinstance(blocks, ArrowCovariance)
    jtj, _ = arrow.dense()
    jtj = np.asarray(jtj)
    scale = np.sqrt(np.diag(jtj))
    scale = np.where(scale > 0.0, scale, 1.0)
    ref = np.linalg.pinv(jtj / np.outer(scale, scale), rcond=1e-13, hermitian=True)
    ref = ref / np.outer(scale, scale)
    close(blocks.dense(), ref, "the inverse")
    if singular:
        j = block_index(3, 5, 4)[2, 1]
        # zero but for the round-off of the blocks' eigenvectors
        assert abs(blocks.diagonal()[j]) < 1e-20 * np.abs(ref).max()
        assert np.abs(blocks.column(j)).max() < 1e-14 * np.abs(ref).max()
        assert ratio < 1e-12
    else:
        assert np.max(np.abs(blocks.dense() @ jtj - np.eye(jtj.shape[0]))) < 1e-10
        check_every_operation(blocks)


def test_nothing_of_size_p_by_p_is_kept():
    """The blocks' memory is linear in the traces: no array with a dimension p."""
    arrow = random_arrow(1, s=3, m=40, nb=4, rows=20)
    blocks, _, _ = inverse_and_weakest(arrow, 3)
    p = blocks.size
    fields = [getattr(blocks, f.name) for f in dataclasses.fields(blocks)]
    assert all(p not in np.shape(a) for a in fields)
    assert sum(np.size(a) for a in fields) < 0.1 * p * p


@pytest.fixture(scope="module")
def fitted():
    """(c) a real fit: the small design's, seed 1 (noise-only), and its normal equations
    at the optimum."""
    _, run = small_fit(1)
    result = run.chosen
    model = result.model
    z = np.asarray(result.z)
    normal = _program.run_lm(model, z, np.ones(z.size, bool), result.phi, 0).normal
    return result, normal


def test_a_real_fits_blocks_are_the_dense_pseudo_inverse(fitted):
    result, normal = fitted
    s = result.model.n_shared
    blocks, _, _ = inverse_and_weakest(normal, s)
    ref, _, _ = inverse_and_weakest(normal.as_dense(), s)
    assert isinstance(blocks, ArrowCovariance) and isinstance(ref, DenseCovariance)
    # relative to each pair's own scale: the correlation scale of the reference
    sd = np.sqrt(np.diag(ref.matrix))
    err = np.abs(blocks.dense() - ref.matrix) / np.outer(sd, sd)
    assert err.max() < 1e-8, err.max()  # pinv of the whole against block elimination
    check_every_operation(blocks, seed=1)
    # the fit's own covariance: sigma^2 times these blocks
    sigma2 = result.cov_z.shared[0, 0] / blocks.shared[0, 0]
    close(result.cov_z.dense(), blocks.scaled(sigma2).dense())


def test_every_reader_gives_what_the_dense_matrix_gave(fitted):
    """Intervals' starts and standard errors, derived quantities' variances, the
    conditioning shrinkage and the draws of the predictions: on the blocks and on the
    dense matrix."""
    result, _ = fitted
    model = result.model
    assert isinstance(result.cov_z, ArrowCovariance)
    dense = dataclasses.replace(result, cov_z=DenseCovariance(result.cov_z.dense(), model.n_shared))
    s, k = model.n_shared, model.n_physical
    for i in range(k):
        zi = float(result.z[i]) + 0.3
        close(profile_start(result, i, zi), profile_start(dense, i, zi), model.names[i])
    close(result.cov_z.diagonal(), np.diag(dense.cov_z.matrix), "standard errors")
    close(conditioning_shrinkage(result.cov_z, s), conditioning_shrinkage(dense.cov_z, s), "shrink")
    a = draws_from_covariance(model, result.z, result.cov_z, 300, 4)
    b = draws_from_covariance(model, result.z, dense.cov_z, 300, 4)
    for name in a.values:
        close(a.values[name], b.values[name], name)
    # the fit's standard errors and correlations are those of the dense matrix
    se = np.sqrt(np.diag(dense.cov_z.matrix))
    for i, spec in enumerate(model.shared_params[:k]):
        est = result.estimates[spec.name]
        assert est.std_error == pytest.approx(abs(float(spec.slope(result.z[i]))) * se[i], rel=REL)
    close(result.correlation, dense.cov_z.matrix[:s, :s] / np.outer(se[:s], se[:s]))


def test_state_files_hold_blocks_and_an_old_dense_folder_predicts_the_same(
    small_fit_folder, tmp_path
):
    """A fit folder holds the blocks, no (p, p) array; the same folder with the dense
    ``cov_z`` alone (as written before the blocks) loads to the same matrix and predicts
    identically."""
    new = tmp_path / "new"
    shutil.copytree(small_fit_folder, new)
    with np.load(new / FIT_STATE.name) as npz:
        arrays = {key: np.asarray(npz[key]) for key in npz.files}
    p = arrays["z"].size
    assert set(STATE_KEYS) <= set(arrays) and "cov_z" not in arrays
    assert all(a.shape != (p, p) for a in arrays.values())
    fit = idtool.load_fit(new)
    assert isinstance(fit.cov_z, ArrowCovariance)
    old = tmp_path / "old"
    shutil.copytree(new, old)
    state = {key: a for key, a in arrays.items() if key not in STATE_KEYS}
    np.savez(old / FIT_STATE.name, **state, cov_z=fit.cov_z.dense())
    fit_old = idtool.load_fit(old)
    assert isinstance(fit_old.cov_z, DenseCovariance)
    np.testing.assert_array_equal(fit_old.cov_z.dense(), fit.cov_z.dense())
    loads, amps = [270.0, 500.0], [0.5, 0.7]
    a = fit.predict(loads, amps, max_draws=300)
    b = fit_old.predict(loads, amps, max_draws=300)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.median, x.ci95, x.new_trace) == (y.median, y.ci95, y.new_trace)
    # saved again, an old folder keeps its dense matrix (it has no blocks to write)
    again = fit_old.save(tmp_path / "again", plots=False)
    with np.load(again / FIT_STATE.name) as npz:
        assert "cov_z" in npz.files and STATE_KEYS[0] not in npz.files
