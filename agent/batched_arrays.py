"""What the batched engine's modules share (agent/batched.py): arrays with a leading axis of M
draws stacked, taken for a sub-stack of draws and put back (:func:`stack`, :func:`_take`,
:func:`_put`), the sensor history kept per agent, and the engine's refusals."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


HISTORY = 64  # sensor samples kept per agent for View.series (the runtime's inbox keeps as many)


class HistorySplit(Exception):
    """A law read the sensor history in a step whose draws hold different histories
    (_tick_draws then steps them apart)."""


class Unsupported(ValueError):
    """A scenario (or a request of its algorithm) that lockstep cannot reproduce."""


def stack(values: Sequence[Any]) -> Any:
    """Per-draw values (states, initial values) as one value with a leading draw axis:
    dataclasses field by field, mappings key by key, numbers and arrays stacked."""
    v0 = values[0]
    if dataclasses.is_dataclass(v0) and not isinstance(v0, type):
        return type(v0)(**{f.name: stack([getattr(v, f.name) for v in values]) for f in dataclasses.fields(v0)})
    if isinstance(v0, Mapping):
        keys = list(v0)
        if any(list(v) != keys for v in values):
            raise Unsupported("draws whose states hold different keys")
        return {k: stack([v[k] for v in values]) for k in keys}
    if v0 is None:
        if any(v is not None for v in values):
            raise Unsupported("draws whose states differ in what is set")
        return None
    if isinstance(v0, tuple):
        if any(len(v) != len(v0) for v in values):
            raise Unsupported("draws whose states differ in length")
        return tuple(stack(list(col)) for col in zip(*values, strict=True))
    return np.stack([np.asarray(v, dtype=float) for v in values])


def _same(a: Any, b: Any) -> bool:
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else bool(a == b)


SUB_ROWS = 16


def _sub_rows(idx: np.ndarray) -> np.ndarray:
    """The rows of a group's sub-stack: its draws ``idx``, padded to SUB_ROWS with the first."""
    return idx if len(idx) >= SUB_ROWS else np.concatenate([idx, np.full(SUB_ROWS - len(idx), idx[0])])


def _take(x: Any, rows: np.ndarray, M: int) -> Any:
    """The draws ``rows`` of ``x`` (M draws), through dataclasses, mappings and tuples: every
    array with the leading draw axis (shape[0] == M, as :func:`_where` and :func:`stack`) gathered;
    what has no draw axis is the same in every draw and kept."""
    if type(x) is np.ndarray:
        return x[rows] if x.ndim and x.shape[0] == M else x
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return dataclasses.replace(x, **{f.name: _take(getattr(x, f.name), rows, M) for f in dataclasses.fields(x) if f.init})
    if isinstance(x, Mapping):
        return {k: _take(v, rows, M) for k, v in x.items()}
    if isinstance(x, tuple | list):
        return type(x)(_take(v, rows, M) for v in x)
    if isinstance(x, np.ndarray) and x.ndim >= 1 and x.shape[0] == M:
        return x[rows]
    return x


def _put(full: Any, sub: Any, idx: np.ndarray, M: int, m: int) -> Any:
    """``full`` (M draws) with its draws ``idx`` replaced by the first ``len(idx)`` rows of
    ``sub``, a sub-stack of ``m`` rows (:func:`_sub_rows`) stepped from ``_take(full, rows)``.
    What the step created (a mapping's new key, a value that was None) is spread to every draw
    from the group's rows (the others' values are valid numbers no later step of theirs reads
    before setting its own: as :func:`_where` keeps ``a`` where ``b`` lacks it); a value
    without a draw axis that now differs between draws gets one."""
    if full is sub:
        return full
    if type(sub) is np.ndarray and type(full) is np.ndarray and sub.ndim and full.ndim and sub.shape[0] == m and full.shape == (M, *sub.shape[1:]):
        out = full.astype(np.result_type(full, sub), copy=True)  # the common case: per draw, in both
        out[idx] = sub[: len(idx)]
        return out
    if _kind(full) != _kind(sub):  # e.g. None before the first step
        return _spread(sub, idx, M, m)
    if dataclasses.is_dataclass(sub) and not isinstance(sub, type):
        return dataclasses.replace(full, **{f.name: _put(getattr(full, f.name), getattr(sub, f.name), idx, M, m) for f in dataclasses.fields(sub) if f.init})
    if isinstance(sub, Mapping):
        return {k: (_put(full[k], v, idx, M, m) if k in full else _spread(v, idx, M, m)) for k, v in sub.items()}
    if isinstance(sub, tuple | list):
        if len(sub) != len(full):
            return full  # e.g. the jump events of one group's step: counted per group, not merged (_where)
        return type(sub)(_put(f, s, idx, M, m) for f, s in zip(full, sub, strict=True))
    n = len(idx)
    if isinstance(sub, np.ndarray) and sub.ndim >= 1 and sub.shape[0] == m:  # per draw
        inner, part = sub.shape[1:], sub[:n]
    else:  # the same in every draw of the group
        if isinstance(full, np.ndarray) and full.ndim >= 1 and full.shape[0] == M and full.shape[1:] == np.shape(sub):
            inner, part = np.shape(sub), sub
        elif _same(full, sub):
            return sub
        else:
            inner, part = np.shape(sub), sub
    if isinstance(full, np.ndarray) and full.shape == (M, *inner):
        out = full.astype(np.result_type(full, part), copy=True)
    elif np.shape(full) == inner:
        out = np.empty((M, *inner), dtype=np.result_type(full, part))
        out[...] = full
    else:
        return _spread(sub, idx, M, m)
    out[idx] = part
    return out


def _kind(x: Any) -> Any:
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return type(x)
    if isinstance(x, Mapping):
        return Mapping
    if isinstance(x, tuple | list):
        return tuple
    return "number" if isinstance(x, np.ndarray | float | int | np.number) else type(x)


def _spread(sub: Any, idx: np.ndarray, M: int, m: int) -> Any:
    """A sub-stack's value for all M draws: draw ``idx[r]`` gets row r, every other draw row 0."""
    where = np.zeros(M, dtype=np.int64)
    where[idx] = np.arange(len(idx))
    return _take(sub, where, m)


def _where(G: np.ndarray, a: Any, b: Any, M: int) -> Any:
    """``a`` in the draws of ``G``, ``b`` in the others, through dataclasses, mappings and tuples;
    an array without the draw axis is the same in every group (no draw's data went into it)."""
    if a is b:
        return a
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return dataclasses.replace(a, **{f.name: _where(G, getattr(a, f.name), getattr(b, f.name), M) for f in dataclasses.fields(a) if f.init})
    if isinstance(a, Mapping):
        return {k: _where(G, v, b[k], M) if k in b else v for k, v in a.items()}
    if isinstance(a, tuple | list):
        if len(a) != len(b):
            return b  # e.g. the jump events of one group's step: counted per group, not merged
        return type(a)(_where(G, x, y, M) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray) and a.ndim >= 1 and a.shape[0] == M:
        return np.where(G.reshape((M,) + (1,) * (a.ndim - 1)), a, b)
    return a
