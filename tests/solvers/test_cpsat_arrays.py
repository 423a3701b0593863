"""Constraints written from arrays mean what they say: with every variable fixed, CP-SAT
finds the model feasible exactly when every row holds by a direct numpy check."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from ortools.sat.python import cp_model

from service.solvers.cpsat_arrays import (
    INT64_MAX,
    INT64_MIN,
    add_clauses,
    add_hints,
    add_linear,
    add_max,
    add_sums,
    minimize,
    negated,
    new_vars,
    solution_of,
)

N_VARS = 6  # integer variables x0..x5, then N_VARS Booleans


def _fixed_model(
    values: np.ndarray, bools: np.ndarray
) -> tuple[cp_model.CpModel, np.ndarray, np.ndarray]:
    """A model whose integer variables and Booleans are fixed at ``values`` and ``bools``."""
    model = cp_model.CpModel()
    ints = new_vars(model, values.size, values, values)
    flags = new_vars(model, bools.size, bools, bools)
    return model, ints, flags


def _feasible(model: cp_model.CpModel) -> bool:
    solver = cp_model.CpSolver()
    solver.parameters.num_workers = 1
    status = solver.solve(model)
    assert status != cp_model.MODEL_INVALID
    return status in (cp_model.OPTIMAL, cp_model.FEASIBLE)


values_st = st.lists(st.integers(-20, 20), min_size=N_VARS, max_size=N_VARS).map(np.array)
bools_st = st.lists(st.integers(0, 1), min_size=N_VARS, max_size=N_VARS).map(np.array)


# A row's domain as this module writes them: at least c, at most c, or a range.
bounds_st = st.one_of(
    st.integers(-40, 40).map(lambda c: (c, INT64_MAX)),
    st.integers(-40, 40).map(lambda c: (INT64_MIN, c)),
    st.tuples(st.integers(-40, 40), st.integers(0, 20)).map(lambda t: (t[0], t[0] + t[1])),
)


@st.composite
def literals_st(draw: st.DrawFn, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` literals as (flag position (count,), negated (count,))."""
    pos = np.array(draw(st.lists(st.integers(0, N_VARS - 1), min_size=count, max_size=count)))
    neg = np.array(draw(st.lists(st.booleans(), min_size=count, max_size=count)), dtype=bool)
    return pos, neg


def _encode(flags: np.ndarray, pos: np.ndarray, neg: np.ndarray) -> np.ndarray:
    return np.where(neg, negated(flags[pos]), flags[pos])


def _truth(bools: np.ndarray, pos: np.ndarray, neg: np.ndarray) -> np.ndarray:
    return bools[pos].astype(bool) ^ neg


@settings(max_examples=60, deadline=None)
@given(values_st, bools_st, st.data())
def test_linear_rows_hold_exactly_where_numpy_says(
    values: np.ndarray, bools: np.ndarray, data: st.DataObject
) -> None:
    rows = data.draw(st.integers(1, 5))
    width = data.draw(st.integers(1, 3))
    n_enforce = data.draw(st.integers(0, 2))
    cols = [
        np.array(data.draw(st.lists(st.integers(0, N_VARS - 1), min_size=rows, max_size=rows)))
        for _ in range(width)
    ]
    coeffs = data.draw(st.lists(st.integers(-3, 3), min_size=width, max_size=width))
    bounds = data.draw(st.lists(bounds_st, min_size=rows, max_size=rows))
    lo, hi = (np.array(side) for side in zip(*bounds, strict=True))
    enforce = [data.draw(literals_st(rows)) for _ in range(n_enforce)]

    model, ints, flags = _fixed_model(values, bools)
    add_linear(
        model, [ints[c] for c in cols], coeffs, lo, hi, [_encode(flags, *e) for e in enforce]
    )

    total = sum(k * values[c] for k, c in zip(coeffs, cols, strict=True))  # (rows,)
    active = np.logical_and.reduce([_truth(bools, *e) for e in enforce] + [np.ones(rows, bool)])
    holds = ~active | ((lo <= total) & (total <= hi))
    assert _feasible(model) == bool(holds.all())


def _csr(data: st.DataObject, rows: int, high: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of 0-4 items in [0, high): (start (rows+1,), items)."""
    sizes = data.draw(st.lists(st.integers(0, 4), min_size=rows, max_size=rows))
    items = np.array(
        data.draw(st.lists(st.integers(0, high - 1), min_size=sum(sizes), max_size=sum(sizes))),
        dtype=np.int64,
    )
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64), items


@settings(max_examples=60, deadline=None)
@given(values_st, bools_st, st.data())
def test_sums_clauses_and_maxima_hold_exactly_where_numpy_says(
    values: np.ndarray, bools: np.ndarray, data: st.DataObject
) -> None:
    rows = data.draw(st.integers(1, 4))
    kind = data.draw(st.sampled_from(["sums", "clauses", "max"]))
    model, ints, flags = _fixed_model(values, bools)
    start, items = _csr(data, rows, N_VARS)
    spans = [slice(a, b) for a, b in zip(start[:-1], start[1:], strict=True)]
    if kind == "sums":
        lo = np.array(data.draw(st.lists(st.integers(-30, 30), min_size=rows, max_size=rows)))
        hi = lo + np.array(data.draw(st.lists(st.integers(0, 30), min_size=rows, max_size=rows)))
        add_sums(model, start, ints[items], lo, hi)
        totals = np.array([values[items[s]].sum() for s in spans])
        holds = (lo <= totals) & (totals <= hi)
    elif kind == "clauses":
        neg = np.array(
            data.draw(st.lists(st.booleans(), min_size=items.size, max_size=items.size)), dtype=bool
        )
        add_clauses(model, start, _encode(flags, items, neg))
        truth = _truth(bools, items, neg)
        holds = np.array([truth[s].any() for s in spans])
    else:
        targets = np.array(
            data.draw(st.lists(st.integers(0, N_VARS - 1), min_size=rows, max_size=rows))
        )
        add_max(model, ints[targets], start, ints[items])
        holds = np.array(
            [
                values[t] == max([0, *values[items[s]].tolist()])
                for t, s in zip(targets, spans, strict=True)
            ]
        )
    assert _feasible(model) == bool(holds.all())


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(-9, 9), st.integers(0, 9), st.integers(0, 5)), min_size=1, max_size=6
    ),
    st.integers(-50, 50),
)
def test_minimize_reaches_each_lower_bound_and_reports_the_offset(
    rows: list[tuple[int, int, int]], offset: int
) -> None:
    lo = np.array([r[0] for r in rows])
    hi = lo + np.array([r[1] for r in rows])
    coeffs = np.array([r[2] for r in rows])
    model = cp_model.CpModel()
    x = new_vars(model, lo.size, lo, hi)
    add_hints(model, x, hi)  # a feasible hint: the worst point
    minimize(model, x, coeffs, offset)
    solver = cp_model.CpSolver()
    assert solver.solve(model) == cp_model.OPTIMAL
    assert solver.objective_value == float(offset + (coeffs * lo).sum())
    chosen = solution_of(solver)[x]
    assert np.all(chosen[coeffs > 0] == lo[coeffs > 0])
    assert np.all((lo <= chosen) & (chosen <= hi))


def test_negation_is_its_own_inverse_and_never_a_variable_index() -> None:
    literals = np.arange(10)
    assert np.array_equal(negated(negated(literals)), literals)
    assert np.all(negated(literals) < 0)
