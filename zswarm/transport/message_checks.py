"""The checks of the wire's messages (zswarm.transport.messages): the version, the bounds every
value is held to, and the validators of arrays, id maps, named values and counters that each
kind's ``__post_init__`` runs, on a decoded payload and on a message a sender builds alike."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from zswarm.math.kernels import (  # CHECK_*: what the C checks of an array besides its values
    CHECK_NONE,
    CHECK_ROTATION,
    CHECK_UNIT,
    f8_ok,
    idmap_ok,
    named_decoded,
)
from zswarm.math.limits import MAX_ABS, ROT_TOL
from zswarm.math.so3 import _rotation_ok, rotations_ok

VERSION = 5  # 2: open edge messages; 3: inc, bounds; 4: sense fields named as the sensors; 5: typed Structs, est as the SPEC declares


class MessageError(ValueError):
    """A message that is not a valid zswarm message."""


# Bounds on every field: a message that decodes but carries a value no experiment can produce
# is malformed, not something for an agent's math to choke on (a gyro of 1e200 killed an agent
# in so3.exp).
MAX_SEQ = 1 << 53  # seq and inc are in [0, 2**53): integers JSON (and so the viewers) carry exactly
MAX_ID = (1 << 31) - 1  # src and agent ids are in [0, 2**31)
MAX_IDS = 4096  # entries of a map keyed by agent or edge id, of truth's ids, of a jump list
UNIT_TOL = 1e-6  # | |b| − 1 | of every bearing
MAX_STR = 4096
MAX_OPEN = 64  # named values of a message (an algorithm's edge fields, command, estimate)
MAX_NAME = 64
MAX_VALUE_LEN = 4096  # elements of one named array
MAX_ARRAY = 1 << 17  # elements of any array (a truth of MAX_IDS rows of 3x3 is 36 864)
MAX_COUNTER_DEPTH = 6
MAX_COUNTER_ITEMS = 20000
ENVELOPE = ("type", "v", "src", "seq", "inc", "t")
JUMP_OWNERS = ("edge", "agent")  # a hybrid variable per tree edge (ξ_k), or the agent's own (ζ_i)
_ENVELOPE = frozenset(ENVELOPE)
_F8 = np.dtype("<f8")
_VEC, _MAT = [3], [3, 3]  # the shapes of most arrays, as a payload writes them


def decoded_ok(a: Any, n: int, check: int = CHECK_NONE) -> bool:
    """``a`` is a decoded array of n (3: shape (3,); 9: (3, 3)) values that passes the checks of
    :func:`_fixed` and :func:`_check_values` (and :func:`_unit` or :func:`_rotation`), checked in C;
    False when it does not or the C loops are not built: then the Python checks it."""
    return f8_ok is not None and f8_ok(a, n, check, MAX_ABS, UNIT_TOL if check == CHECK_UNIT else ROT_TOL)


def _fail(field: str, problem: str) -> MessageError:
    return MessageError(f"{field}: {problem}")


def _array(v: Any, field: str) -> np.ndarray:
    """A float64 array as a message holds it: read-only, decoded from ``[shape, bytes]`` or
    copied from what a sender passed (which it may change afterwards)."""
    if type(v) is np.ndarray:
        if v.dtype is _F8 and not v.flags.writeable:
            return v
        a = np.array(v, dtype=_F8)
    elif type(v) is list and len(v) == 2 and type(v[1]) is bytes:
        shape = v[0]
        if type(shape) is not list or len(shape) > 4 or not all(type(d) is int and 0 <= d <= MAX_ARRAY for d in shape):
            raise _fail(field, f"bad shape {shape!r}")
        n = math.prod(shape)
        if n > MAX_ARRAY or len(v[1]) != 8 * n:
            raise _fail(field, f"{len(v[1])} bytes for shape {tuple(shape)}")
        a = np.frombuffer(v[1], dtype=_F8)
        return a.reshape(shape) if len(shape) != 1 else a
    else:
        try:
            a = np.array(v, dtype=_F8)
        except (TypeError, ValueError):
            raise _fail(field, "expected [shape, bytes] or an array of numbers") from None
    if a.ndim > 4 or a.size > MAX_ARRAY:
        raise _fail(field, f"an array of shape {a.shape}")
    a.flags.writeable = False
    return a


def _check_values(a: np.ndarray, field: str) -> None:
    """Every number finite and within ±MAX_ABS."""
    if a.size <= 64:
        xs = a.ravel().tolist()
        # NaN or inf make the sum non-finite, and so do finite values whose sum overflows (all
        # of them beyond MAX_ABS then): the message says which.
        if xs and not (math.isfinite(sum(xs)) and max(xs) <= MAX_ABS and min(xs) >= -MAX_ABS):
            raise _fail(field, "non-finite values" if not all(map(math.isfinite, xs)) else f"values beyond ±{MAX_ABS:g}")
    elif a.size and not np.abs(a).max() <= MAX_ABS:  # False for NaN too
        raise _fail(field, "non-finite values" if not np.isfinite(a).all() else f"values beyond ±{MAX_ABS:g}")


def _shaped(v: Any, shape: tuple[int, ...], field: str) -> np.ndarray:
    """An array of ``shape`` (-1: any length there), its values checked."""
    a = _array(v, field)
    if a.shape != shape and (len(a.shape) != len(shape) or any(w != -1 and w != g for w, g in zip(shape, a.shape, strict=True))):
        raise _fail(field, f"shape {a.shape}, expected {shape}")
    _check_values(a, field)
    return a


def _fixed(v: Any, shape: tuple[int, ...], field: str) -> np.ndarray:
    """:func:`_shaped` for a fixed shape, its values left to :func:`_values_ok` (one check for
    every array of a message: most are 3-vectors and 3x3 matrices, where each call costs)."""
    if type(v) is np.ndarray and v.dtype is _F8 and not v.flags.writeable and v.shape == shape:
        return v  # decoded: a read-only view of the payload's bytes
    a = _array(v, field)
    if a.shape != shape:
        raise _fail(field, f"shape {a.shape}, expected {shape}")
    return a


def _values_ok(arrays: list[np.ndarray]) -> list[float] | None:
    """Every number of ``arrays`` (all small) as one list, or None when some is not finite or
    beyond ±MAX_ABS (then :func:`_check_values` on each names it).  NaN or inf make the sum
    non-finite, and so do finite values whose sum overflows (beyond MAX_ABS every one)."""
    xs: list[float] = []
    for a in arrays:
        xs += a.tolist() if a.ndim == 1 else a.ravel().tolist()
    return xs if not xs or (math.isfinite(sum(xs)) and max(xs) <= MAX_ABS and min(xs) >= -MAX_ABS) else None


def _rotation(a: np.ndarray, field: str) -> None:
    ok = _rotation_ok(a.ravel().tolist(), ROT_TOL) if a.shape == (3, 3) else rotations_ok(a, ROT_TOL)
    if not ok:
        raise _fail(field, f"not a rotation (R^T R = I, det R = 1 within {ROT_TOL:g})")


def _unit(a: np.ndarray, field: str) -> None:
    x, y, z = a.tolist()
    if not abs(x * x + y * y + z * z - 1.0) <= 2 * UNIT_TOL:  # |b|² − 1 ≈ 2(|b| − 1); False for NaN
        raise _fail(field, f"not a unit vector (|b| = 1 within {UNIT_TOL:g})")


def _id(j: Any) -> bool:
    return type(j) is int and 0 <= j <= MAX_ID


def _number(x: Any, field: str) -> float:
    """A finite number within ±MAX_ABS (not a bool), as a float."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.floating)) or not -MAX_ABS <= x <= MAX_ABS:
        raise _fail(field, f"expected a finite number within ±{MAX_ABS:g}")
    return float(x)


def _string(x: Any, field: str) -> str:
    if type(x) is not str or len(x) > MAX_STR:
        raise _fail(field, f"expected a string of at most {MAX_STR} characters")
    return x


def _id_map(v: Any, field: str, shape: tuple[int, ...], check: Any = None) -> dict[int, np.ndarray]:
    """{id: array of ``shape``}; ``check`` on each: ``_unit`` (a unit vector) or ``_rotation``."""
    c, tol = (CHECK_UNIT, UNIT_TOL) if check is _unit else (CHECK_ROTATION, ROT_TOL) if check is _rotation else (CHECK_NONE, 0.0)
    if idmap_ok is not None and (shape == (3,) or shape == (3, 3)):
        # A decoded map, checked in C with the verdicts below (zswarm/math/_kernels.c): a sense
        # packet's 17.8 -> 9 µs hot (2026-12-06).  False: anything else, checked below.
        if idmap_ok(v, 3 if shape == (3,) else 9, c, MAX_ABS, tol, MAX_ID, MAX_IDS):
            return dict(v)
    if type(v) is not dict or len(v) > MAX_IDS or not all(map(_id, v)):
        raise _fail(field, f"expected a map of at most {MAX_IDS} ids to arrays of shape {shape}")
    vals = list(v.values())
    if vals and all(type(x) is np.ndarray and x.dtype is _F8 and x.shape == shape and x.flags.writeable for x in vals):
        # A sender's arrays: copied at once into one read-only stack, its rows the entries.
        stack = np.array(vals)
        stack.flags.writeable = False
        out = dict(zip(v, stack, strict=True))
        if idmap_ok is not None and (shape == (3,) or shape == (3, 3)) and idmap_ok(out, 3 if shape == (3,) else 9, c, MAX_ABS, tol, MAX_ID, MAX_IDS):
            return out  # its rows: read-only views, checked in C as a decoded map's
        xs = stack.ravel().tolist()
        if not (math.isfinite(sum(xs)) and max(xs) <= MAX_ABS and min(xs) >= -MAX_ABS):
            xs = None
    else:
        out = {}
        for j, x in v.items():  # decoded: read-only views of the payload (_fixed inlined: most maps are of these)
            out[j] = x if type(x) is np.ndarray and x.shape == shape and x.dtype is _F8 and not x.flags.writeable else _fixed(x, shape, f"{field}[{j}]")
        xs = _values_ok(list(out.values()))
    if xs is None:
        for j, a in out.items():
            _check_values(a, f"{field}[{j}]")
    elif check is _unit:
        for q, j in enumerate(out):
            x, y, z = xs[3 * q : 3 * q + 3]
            if not abs(x * x + y * y + z * z - 1.0) <= 2 * UNIT_TOL:  # |b|² − 1 ≈ 2(|b| − 1)
                raise _fail(f"{field}[{j}]", f"not a unit vector (|b| = 1 within {UNIT_TOL:g})")
    elif check is _rotation:
        for q, j in enumerate(out):
            if not _rotation_ok(xs[9 * q : 9 * q + 9], ROT_TOL):
                raise _fail(f"{field}[{j}]", f"not a rotation (R^T R = I, det R = 1 within {ROT_TOL:g})")
    return out


def _named(v: Any, field: str) -> dict[str, float | np.ndarray]:
    """Named values: each a finite number or a float64 array of at most 4 dimensions and
    MAX_VALUE_LEN elements."""
    if named_decoded is not None:
        # A decoded map of numbers, 3-vectors and 3x3 matrices (an edge's, an estimate's), checked
        # in C with the verdicts below, its arrays made as they are below; None: checked here.
        done = named_decoded(v, _ENVELOPE, MAX_OPEN, MAX_NAME, MAX_ABS)
        if done is not None:
            return done
    if type(v) is not dict or len(v) > MAX_OPEN or not all(type(n) is str and 0 < len(n) <= MAX_NAME and n not in ENVELOPE for n in v):
        raise _fail(field, f"expected a map of at most {MAX_OPEN} names (of at most {MAX_NAME} characters, not {', '.join(ENVELOPE)}) to values")
    out: dict[str, float | np.ndarray] = {}
    small: list[np.ndarray] = []  # checked at once (_values_ok)
    for n, x in v.items():
        t = type(x)
        if t is list and len(x) == 2 and type(x[1]) is bytes and f8_ok is not None:
            # Decoded: a 3-vector or a 3x3 matrix as _array makes it (read-only, over the payload),
            # its values checked in C (an edge message's checks 10 -> 4 µs hot, 2026-12-06).
            shape, data = x
            if shape == _VEC and len(data) == 24:
                a = np.frombuffer(data, dtype=_F8)
                if f8_ok(a, 3, CHECK_NONE, MAX_ABS, 0.0):
                    out[n] = a
                    continue
            elif shape == _MAT and len(data) == 72:
                a = np.frombuffer(data, dtype=_F8).reshape(3, 3)
                if f8_ok(a, 9, CHECK_NONE, MAX_ABS, 0.0):
                    out[n] = a
                    continue
        if t is float:
            if not -MAX_ABS <= x <= MAX_ABS:  # False for NaN
                raise _fail(f"{field}.{n}", f"expected a finite number within ±{MAX_ABS:g}")
            out[n] = x
        elif isinstance(x, (int, float, np.floating)) and t is not bool:
            out[n] = _number(x, f"{field}.{n}")
        else:
            if t is np.ndarray and x.dtype is _F8 and x.ndim <= 4 and x.size <= 64:
                a = x
                if a.flags.writeable:  # a sender's: copied (it may change it afterwards)
                    a = a.copy()
                    a.flags.writeable = False
            else:
                a = _array(x, f"{field}.{n}")
                if a.size > MAX_VALUE_LEN:
                    raise _fail(f"{field}.{n}", f"more than {MAX_VALUE_LEN} elements")
            out[n] = a
            if a.size <= 64:
                small.append(a)
            else:
                _check_values(a, f"{field}.{n}")
    if small and f8_ok is not None:  # the 3-vectors and 3x3 matrices (read-only now) in C
        small = [a for a in small if not (a.shape == (3,) and f8_ok(a, 3, CHECK_NONE, MAX_ABS, 0.0) or a.shape == (3, 3) and f8_ok(a, 9, CHECK_NONE, MAX_ABS, 0.0))]
    if _values_ok(small) is None:
        for n, a in out.items():
            if type(a) is np.ndarray:
                _check_values(a, f"{field}.{n}")
    return out


def _counters(v: Any, field: str) -> dict[str, Any]:
    """A process's counters: names to numbers, strings, booleans, None, lists and maps of those,
    bounded (``counters = 5`` used to pass and make the report raise after the run)."""
    if type(v) is not dict:
        raise _fail(field, "expected a map of names to counters")
    left = [MAX_COUNTER_ITEMS]

    def check(x: Any, where: str, depth: int) -> None:
        left[0] -= 1
        if left[0] < 0:
            raise _fail(field, f"more than {MAX_COUNTER_ITEMS} entries")
        if depth > MAX_COUNTER_DEPTH:
            raise MessageError(f"{where}: nested deeper than {MAX_COUNTER_DEPTH}")
        t = type(x)
        if t is dict:
            for n, y in x.items():
                if type(n) is not str or len(n) > 256:
                    raise MessageError(f"{where}: keys must be names (strings of at most 256 characters)")
                check(y, f"{where}.{n}", depth + 1)
        elif t is list or t is tuple:
            for i, y in enumerate(x):
                check(y, f"{where}[{i}]", depth + 1)
        elif x is not None and t not in (int, float, str, bool):
            raise MessageError(f"{where}: expected a number, a string, a list or a map")
        elif t is str and len(x) > MAX_STR:
            raise MessageError(f"{where}: a string of more than {MAX_STR} characters")
        elif t is float and not math.isfinite(x):
            raise MessageError(f"{where}: not finite")

    check(v, field, 0)
    return v
