"""The structured NLP's derivatives against CasADi's own differentiation of the whole lap."""

from __future__ import annotations

import math
import os

import casadi as ca
import numpy as np
import pytest

from racing_lib.jit import c_compiler
from racing_lib.model import ModelOptions, ModelParams
from racing_lib.planning.time_optimal import TimeOptimalSettings, _shape_settings
from racing_lib.planning.time_optimal_nlp import (
    NLP_SCALE,
    StructuredNLP,
    clear_interval_caches,
    interval_functions,
)

N = 9  # small enough for dense comparisons, and the last interval wraps round to node 0


@pytest.fixture(scope="module", params=[ModelOptions(), ModelOptions(lateral_weight_transfer=True)])
def pair(request):
    rng = np.random.default_rng(3)
    fns = interval_functions(ModelParams(), request.param, _shape_settings(TimeOptimalSettings()))
    # the flat graph is differentiated by CasADi: its interval functions are never compiled
    flat_fns = interval_functions(
        ModelParams(), request.param, _shape_settings(TimeOptimalSettings(graph="sx"))
    )
    kappa = 0.02 * np.sin(np.linspace(0.0, 2.0 * math.pi, N, endpoint=False))
    theta = 0.01 * np.cos(np.linspace(0.0, 2.0 * math.pi, N, endpoint=False))
    ds = rng.uniform(2.5, 3.5, N)
    s = np.concatenate([[0.0], np.cumsum(ds[:-1])])
    structured = StructuredNLP(fns, kappa, theta, s, ds, t_ref=5.0)
    flat = StructuredNLP(flat_fns, kappa, theta, s, ds, t_ref=5.0, graph="sx")
    # A point away from every singularity: moving forward, moderate slip and steering.
    z = np.empty((len(NLP_SCALE), N))
    z[0] = rng.uniform(15.0, 40.0, N)
    z[1:] = rng.normal(0.0, 0.3, (len(NLP_SCALE) - 1, N)) * NLP_SCALE[1:, None]
    x = (z / NLP_SCALE[:, None]).ravel(order="F")
    lam_g = rng.normal(0.0, 1.0, len(structured.lbg))
    return structured, flat, x, lam_g


def test_the_objective_and_constraints_are_the_flat_graphs(pair):
    structured, flat, x, _ = pair
    for key in ("f", "g"):
        mine = ca.Function("a", [structured.nlp["x"]], [structured.nlp[key]])(x)
        theirs = ca.Function("b", [flat.nlp["x"]], [flat.nlp[key]])(x)
        np.testing.assert_allclose(np.asarray(mine), np.asarray(theirs), rtol=1e-12, atol=1e-12)


def test_the_assembled_gradient_jacobian_and_hessian_equal_casadis(pair):
    structured, flat, x, lam_g = pair
    xs, f, g = flat.nlp["x"], flat.nlp["f"], flat.nlp["g"]
    sigma = 0.7
    grad_ref = ca.Function("g", [xs], [ca.gradient(f, xs)])(x)
    jac_ref = ca.Function("j", [xs], [ca.jacobian(g, xs)])(x)
    hess_ref = ca.Function("h", [xs], [ca.hessian(sigma * f + ca.dot(ca.DM(lam_g), g), xs)[0]])(x)

    der = structured.derivatives
    _, grad = der["grad_f"](x, [])
    _, jac = der["jac_g"](x, [])
    hess = der["hess_lag"](x, [], sigma, lam_g)
    np.testing.assert_allclose(np.asarray(grad), np.asarray(grad_ref), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.asarray(jac), np.asarray(jac_ref), rtol=1e-10, atol=1e-10)
    # IPOPT is given the upper triangle only; the full matrix is that plus its strict transpose.
    upper = np.asarray(ca.densify(hess))
    assert np.allclose(np.tril(upper, -1), 0.0)
    full = upper + np.triu(upper, 1).T
    np.testing.assert_allclose(full, np.asarray(hess_ref), rtol=1e-9, atol=1e-9)
    # Every node is coupled to its neighbours only (and the last to the first).
    assert np.count_nonzero(full[:7, 7 * 2 : 7 * (N - 1)]) == 0
    assert np.count_nonzero(full[:7, -7:]) > 0


def test_interval_functions_are_built_once_per_parameter_set():
    st = _shape_settings(TimeOptimalSettings())
    assert interval_functions(ModelParams(), ModelOptions(), st) is interval_functions(
        ModelParams(), ModelOptions(), st
    )
    # Solver options and the grid do not shape an interval.
    other = _shape_settings(TimeOptimalSettings(spacing=2.0, max_iter=5, tol=1e-3))
    assert interval_functions(ModelParams(), ModelOptions(), other) is interval_functions(
        ModelParams(), ModelOptions(), st
    )


@pytest.mark.parametrize("name", ["con", "con_jac", "obj_grad", "hess"])
def test_the_compiled_functions_are_the_interpreted_ones_to_the_bit(name):
    st = TimeOptimalSettings()
    compiled = interval_functions(ModelParams(), ModelOptions(), _shape_settings(st))
    interpreted = interval_functions(
        ModelParams(), ModelOptions(), _shape_settings(TimeOptimalSettings(jit=False))
    )
    fn, ref = getattr(compiled, name), getattr(interpreted, name)
    if c_compiler()[0] is None:
        pytest.skip("no C compiler on this machine: the planner interprets (tested below)")
    assert fn.class_name() == "External" and ref.class_name() == "SXFunction"
    rng = np.random.default_rng(5)
    for _ in range(5):
        args = [
            rng.uniform(0.5, 1.5, 7),  # scaled variables of node a and node b
            rng.uniform(0.5, 1.5, 7),
            [0.02 * rng.normal(), 0.01 * rng.normal(), 100.0],  # kappa, theta, s
            [0.02 * rng.normal(), 0.01 * rng.normal(), 103.0],
            3.0,
        ]
        if name == "hess":
            args += [0.7, rng.normal(0.0, 1.0, compiled.n_con)]
        np.testing.assert_array_equal(np.asarray(fn(*args)), np.asarray(ref(*args)))


@pytest.fixture
def fresh_interval_cache():
    """No interval functions cached before or after the test (it builds them another way)."""
    clear_interval_caches()
    yield
    clear_interval_caches()


@pytest.mark.skipif(os.name != "posix", reason="elsewhere no compiler is tried at all")
@pytest.mark.usefixtures("fresh_interval_cache")
def test_without_a_compiler_the_nlp_is_interpreted_with_one_warning(monkeypatch, caplog):
    monkeypatch.setenv("CC", "/no/such/dir/cc")
    with caplog.at_level("WARNING"):
        fns = interval_functions(
            ModelParams(), ModelOptions(), _shape_settings(TimeOptimalSettings())
        )
    assert fns.hess.class_name() == "SXFunction"
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1, warnings
    # What failed, why, and the two ways out.
    assert "/no/such/dir/cc" in warnings[0] and "TimeOptimalSettings(jit=False)" in warnings[0]
    assert "Install a C compiler" in warnings[0]


def test_other_graphs_compile_nothing():
    for graph in ("sx", "mx"):
        assert not _shape_settings(TimeOptimalSettings(graph=graph)).jit
    assert _shape_settings(TimeOptimalSettings()).jit


def test_only_the_compiled_constraints_may_be_differentiated_by_casadi():
    # nlpsol differentiates the graph of the constraints as it builds the solver; compiled code
    # has no derivatives of its own, so the constraints allow finite differences, and nothing
    # else does: a derivative that is used is always one of the compiled derivative functions.
    if c_compiler()[0] is None:
        pytest.skip("no C compiler on this machine: the planner interprets")
    fns = interval_functions(ModelParams(), ModelOptions(), _shape_settings(TimeOptimalSettings()))
    wa, wb = ca.MX.sym("wa", 7), ca.MX.sym("wb", 7)
    args = [wa, wb, ca.DM([0.01, 0.0, 0.0]), ca.DM([0.01, 0.0, 3.0]), 3.0]
    ca.gradient(ca.sum1(fns.con(*args)), wa)
    lam = ca.DM.ones(fns.n_con)
    with pytest.raises(RuntimeError, match="Derivatives cannot be calculated"):
        ca.gradient(ca.sum1(fns.hess(*args, 1.0, lam)), wa)
