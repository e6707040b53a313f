"""The fit on the arrowhead normal equations (issue 28): the nuisances eliminated per
trace by their Schur complement give the same optimum, covariance and checked intervals
as the dense normal equations (the reference, kept here), on the example."""

import functools

import equinox as eqx
import numpy as np
import pytest
from sample_helpers import random_arrow

import idtool
from idtool._data._blocks import prepare_fit_data
from idtool._fit import _program
from idtool._fit._arrow import Arrow, DenseNormal, block_index, inverse_and_weakest
from idtool._fit._fit import fit_model
from idtool._fit._intervals import check_intervals
from idtool._model._benchmodel import bench_model

# Both paths solve the same equations exactly; they differ in rounding only, and the
# converged points agree far inside the optimiser's own tolerance.
REL = 1e-8


@pytest.fixture(scope="module")
def fits():
    data = prepare_fit_data(idtool.load_dataset(idtool.example_dataset_path()))
    arrow = check_intervals(fit_model(data))
    with pytest.MonkeyPatch.context() as mp:
        dense = functools.partial(_program.level_structure, dense=True)
        mp.setattr(_program, "level_structure", dense)
        reference = check_intervals(fit_model(data))
    return arrow, reference


def test_the_fit_runs_on_arrowhead_blocks_and_the_reference_on_dense_matrices():
    data = prepare_fit_data(idtool.load_dataset(idtool.example_dataset_path()))
    model = bench_model(data)
    z = model.z0()
    out = _program.run_lm(model, z, np.ones(z.size, bool), 0.0, 0)
    assert isinstance(out.normal, Arrow)
    m, k = data.n_traces, model.n_shared
    assert out.normal.d.shape[0] == m and out.normal.a.shape == (k, k)
    with pytest.MonkeyPatch.context() as mp:
        dense = functools.partial(_program.level_structure, dense=True)
        mp.setattr(_program, "level_structure", dense)
        ref = _program.run_lm(model, z, np.ones(z.size, bool), 0.0, 0)
    assert isinstance(ref.normal, DenseNormal)
    scale = np.sqrt(np.outer(np.diag(ref.jtj), np.diag(ref.jtj)))
    assert np.max(np.abs(np.asarray(out.jtj) - ref.jtj) / scale) < 1e-12


def test_estimates_and_intervals_equal_the_dense_reference(fits):
    arrow, reference = fits
    assert arrow.model.names == reference.model.names
    for name, est in reference.estimates.items():
        got = arrow.estimates[name]
        # relative to the value, or to its standard error for values near zero
        tol = REL * max(abs(est.estimate), est.std_error)
        assert got.estimate == pytest.approx(est.estimate, rel=0, abs=tol), name
        assert got.std_error == pytest.approx(est.std_error, rel=REL), name
        np.testing.assert_allclose(got.ci95, est.ci95, rtol=REL, atol=tol, err_msg=name)
        assert got.one_sided == est.one_sided
    assert arrow.phi == pytest.approx(reference.phi, rel=REL)
    assert arrow.rss == pytest.approx(reference.rss, rel=REL)
    cov, ref_cov = arrow.cov_z.dense(), reference.cov_z.dense()
    np.testing.assert_allclose(cov, ref_cov, rtol=0, atol=REL * np.max(np.abs(ref_cov)))
    assert [str(w) for w in arrow.warnings] == [str(w) for w in reference.warnings]


@pytest.mark.parametrize("singular", [False, True])
def test_the_covariance_from_the_schur_complement_is_the_dense_pseudo_inverse(singular):
    arrow = random_arrow(zero=(2, 1))  # trace 2's nuisance 1 moves no residual
    if not singular:  # the zero column filled in
        arrow = eqx.tree_at(lambda a: a.d, arrow, arrow.d + 0.5 * np.eye(arrow.d.shape[-1]))
    blocks, ratio, vector = inverse_and_weakest(arrow, 3)
    ref_blocks, ref_ratio, ref_vector = inverse_and_weakest(arrow.as_dense(), 3)
    inverse, ref_inverse = blocks.dense(), ref_blocks.dense()
    np.testing.assert_allclose(inverse, ref_inverse, rtol=0, atol=1e-12 * np.abs(ref_inverse).max())
    if singular:  # the parameter the data do not move: no variance, named as singular
        j = block_index(3, 5, 4)[2, 1]
        assert abs(inverse[j, j]) < 1e-20 * np.abs(ref_inverse).max()
        assert ratio < 1e-12 and ref_ratio < 1e-12
        assert np.argmax(np.abs(vector)) == np.argmax(np.abs(ref_vector)) == j
    else:
        assert ratio > 1e-6 and ref_ratio > 1e-6
