"""The batched engine's sub-stacks (agent/batched.py _take, _put, _spread): a group of draws
stepped on its own rows, its results written back into the whole stack's draws and nowhere else."""

from dataclasses import dataclass

import numpy as np

from agent.batched_arrays import SUB_ROWS, _put, _spread, _sub_rows, _take


@dataclass(frozen=True)
class State:
    xi: dict[int, np.ndarray]
    coef: dict[int, tuple[np.ndarray, np.ndarray]]
    R: np.ndarray
    note: str
    last: np.ndarray | None = None


M = 40


def _state(rng: np.random.Generator) -> State:
    return State({1: rng.normal(size=M), 2: rng.normal(size=M)}, {1: (rng.normal(size=M), rng.normal(size=M))}, rng.normal(size=(M, 3, 3)), "tree")


def _step(s: State) -> State:
    """A stand-in law step on a stack of any size: every per-draw value changed, a key added."""
    xi = {k: 2.0 * v + 1.0 for k, v in s.xi.items()} | {3: s.xi[1] - s.xi[2]}
    return State(xi, {k: (a + 1.0, b * 3.0) for k, (a, b) in s.coef.items()}, s.R * s.R + 1.0, s.note, s.R[:, 0])


def test_sub_rows_pad_small_groups_with_their_first_draw():
    assert np.array_equal(_sub_rows(np.array([4, 9])), np.array([4, 9] + [4] * (SUB_ROWS - 2)))
    big = np.arange(SUB_ROWS + 3)
    assert _sub_rows(big) is big


def test_a_group_stepped_on_its_rows_is_the_whole_stack_stepped_in_its_draws():
    """Stepping the sub-stack and writing it back gives, in the group's draws, the numbers of
    the whole stack's step (the same elementwise operations on the same rows: the same bits),
    and leaves every other draw as it was."""
    rng = np.random.default_rng(3)
    full = _state(rng)
    idx = np.array([0, 5, 6, 31])
    rows = _sub_rows(idx)
    sub = _step(_take(full, rows, M))
    assert sub.R.shape == (len(rows), 3, 3)
    out = _put(full, sub, idx, M, len(rows))
    whole = _step(full)
    others = np.setdiff1d(np.arange(M), idx)
    for k in (1, 2):
        assert np.array_equal(out.xi[k][idx], whole.xi[k][idx])
        assert np.array_equal(out.xi[k][others], full.xi[k][others])
    assert np.array_equal(out.coef[1][1][idx], whole.coef[1][1][idx])
    assert np.array_equal(out.coef[1][0][others], full.coef[1][0][others])
    assert np.array_equal(out.R[idx], whole.R[idx]) and np.array_equal(out.R[others], full.R[others])
    # What the step created (a new key, a value that was None) reaches every draw, the group's
    # own in its draws (the others' hold valid numbers until their own step sets them).
    assert np.array_equal(out.xi[3][idx], whole.xi[3][idx]) and out.xi[3].shape == (M,)
    assert out.last is not None and np.array_equal(out.last[idx], whole.last[idx]) and out.last.shape == (M, 3)
    assert out.note == "tree"
    # the stack it came from is untouched (the sub-stack's results are written into copies)
    assert not np.shares_memory(out.R, full.R)


def test_a_value_the_same_in_every_draw_gets_a_draw_axis_when_a_group_changes_it():
    full = {"n": 2.0, "v": np.zeros(3)}
    idx = np.array([1, 2])
    out = _put(full, {"n": 3.0, "v": np.zeros(3)}, idx, M, SUB_ROWS)
    assert out["n"].shape == (M,) and set(out["n"][idx]) == {3.0} and out["n"][0] == 2.0
    assert out["v"].shape == (3,)  # unchanged: still one value for all


def test_spread_gives_each_draw_its_row():
    idx = np.array([3, 7])
    sub = np.arange(SUB_ROWS, dtype=float)
    out = _spread(sub, idx, M, SUB_ROWS)
    assert out[3] == 0.0 and out[7] == 1.0 and out[0] == 0.0 and out.shape == (M,)
