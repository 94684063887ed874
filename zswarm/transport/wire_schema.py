"""The wire's message types: their fields and kinds (SCHEMAS), the bounds every value is held
to, and the decoders of each kind of field (transport/wire.py decodes and validates with them)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, TypeGuard

import numpy as np

from zswarm.math.limits import MAX_ABS  # (ROT_TOL: see _check_semantic)

VERSION = 4  # 2: edge messages carry the fields their algorithm declares (open schema); 3: inc, bounds; 4: sense fields named as the sensors (velocity, velocity_body, attitude, position)


class MessageError(ValueError):
    """A message that is not a valid zswarm message."""


class Message(dict):  # type: ignore[type-arg]
    """A message as :func:`decode` returns it: decoded and validated.

    The in-process bus (``zswarm sim``) delivers these to every subscriber instead of
    bytes each would decode and validate again (:func:`message`): :func:`decode` of a
    Message only checks its type.  Receivers must not change it (it is shared): copy
    it to add what they know of it (the arrival time, ...)."""

    __slots__ = ()


# Bounds on every field: a message that decodes but carries a value no experiment can
# produce is malformed, not something for an agent's math to choke on (a gyro of 1e200
# killed an agent in so3.exp).
MAX_SEQ = 1 << 53  # seq and inc are in [0, 2**53): integers JSON (and so the viewers) carry exactly
MAX_ID = (1 << 31) - 1  # src and agent ids are in [0, 2**31)
MAX_IDS = 4096  # entries of a map keyed by agent or edge id, of truth's ids, of a jump list
UNIT_TOL = 1e-6  # | |b| − 1 | of every bearing
MAX_STR = 4096


# field kinds: "int", "float", "str", (shape,) for float64 arrays,
# "vecmap" for {int: float64[3]}, "matmap" for {int: float64[3,3]}, "floatmap" for
# {int: float}, "jumps" for [[edge k, t, ξ before, ξ after], ...], "counters" (a map of names to
# numbers, strings, booleans, None, lists and maps of those: bounded, see _counters)
SCHEMAS: Mapping[str, Mapping[str, Any]] = {
    # world -> agent i, each field named as the sensor is (zswarm.scenario.algorithm.SENSORS): gyro,
    # body-frame bearings b_ij^i, relative attitudes R_ij, inertial velocity v_i, body-frame
    # velocity v_i^i, own attitude R_i and position p_i, body-frame relative positions ⁱp_ij
    # (rel_pos, De Carli et al. (2))
    "sense": {"gyro": (3,), "bearings": "vecmap", "rel_att": "matmap", "velocity": (3,), "velocity_body": (3,), "attitude": (3, 3), "position": (3,), "rel_pos": "vecmap"},
    # agent j -> agent i along edge j->i: the sender's clock, then the fields its
    # algorithm writes on out-edges (SPEC.edge_out: numbers or float64 arrays by
    # name; OPEN below), validated by the receiver against its SPEC.edge_in
    "edge": {"t_local": "float"},
    # agent i -> recorder: its estimate; xi: ξ_k of the edges it heads; jumps since the
    # last est (agent_jumps: of its own hybrid variable, ζ_i of (5.12), k = its id); extra: named values the algorithm reports (σ_i, Ω_i, ...)
    "est": {"t_local": "float", "R_hat": (3, 3), "p_hat": (3,), "extra": "fields", "xi": "floatmap", "jumps": "jumps", "agent_jumps": "jumps"},
    # agent i -> world on cmd/<i>: the sender's clock, then the fields its algorithm
    # sends the plant (SPEC.command: a torque "tau" for the rigid bodies of (5.1)), OPEN
    # below and validated by the world against the plant's inputs
    "cmd": {"t_local": "float"},
    # world -> recorder: ids[k] has attitude R[k], position p[k], true angular velocity w[k]
    # (and, for a rigid-body plant, the torque tau[k] it applied over the last world step;
    # for a kinematic plant, u[k] = [v (body frame), yaw rate] it applied)
    "truth": {"ids": "intlist", "R": (-1, 3, 3), "p": (-1, 3), "w": (-1, 3), "tau": (-1, 3), "u": (-1, 4)},
    # counters of a process
    "stats": {"role": "str", "counters": "counters"},
    # run control; mac: signed with the run's secret when there is one (encode_ctl, decode_ctl)
    "start": {"epoch": "float", "time_scale": "float", "duration": "float", "seed": "int", "run": "str", "mac": "str"},
    "stop": {"reason": "str", "mac": "str"},
    "progress": {"duration": "float", "mac": "str"},
}
_F8 = np.dtype("<f8")
ENVELOPE = ("v", "type", "src", "seq", "inc", "t")
assert not any(k in ENVELOPE for schema in SCHEMAS.values() for k in schema), "a field shadows the envelope"
OPTIONAL = {
    "sense": {"gyro", "bearings", "rel_att", "velocity", "velocity_body", "attitude", "position", "rel_pos"},
    "est": {"R_hat", "p_hat", "extra", "xi", "jumps", "agent_jumps"},
    "truth": {"tau", "u"},
    "start": {"mac"},
    "stop": {"mac"},
    "progress": {"mac"},
}
_OPTIONAL_OF: Mapping[str, frozenset[str]] = {t: frozenset(OPTIONAL.get(t, ())) for t in SCHEMAS}
# Types whose other keys are named values (a finite number or a float64 array), at most
# MAX_OPEN of them: what an algorithm declares, which the receiver validates.
OPEN = frozenset({"edge", "cmd"})
MAX_OPEN = 64
MAX_VALUE_LEN = 4096  # elements of one open array


def _enc_value(v: Any) -> Any:
    """A named value: a number as a float, anything else as a float64 array."""
    if isinstance(v, (int, float, np.floating)) and not isinstance(v, bool):
        return float(v)
    return _arr(np.asarray(v))


_FAST = {(3,): ([3], 24), (3, 3): ([3, 3], 72)}  # the shapes of most fields: a shorter path


def _dec_arr(v: Any, shape: tuple[int, ...], fld: str) -> np.ndarray:
    fast = _FAST.get(shape)
    if fast is not None and type(v) is list and len(v) == 2 and v[0] == fast[0] and type(v[1]) is bytes and len(v[1]) == fast[1]:
        a = np.frombuffer(v[1], dtype="<f8").reshape(shape)
        _check_values(a.ravel().tolist(), fld)
        return a
    if not (type(v) in (list, tuple) and len(v) == 2 and type(v[1]) is bytes and type(v[0]) in (list, tuple)):
        raise MessageError(f"{fld}: expected [shape, bytes]")
    shp = tuple(v[0])
    if len(shp) != len(shape):
        raise MessageError(f"{fld}: bad shape {shp}")
    n = 1
    for want, got in zip(shape, shp, strict=True):
        if type(got) is not int or got < 0:
            raise MessageError(f"{fld}: bad shape {shp}")
        if want != -1 and want != got:
            raise MessageError(f"{fld}: shape {shp}, expected {shape}")
        n *= got
    if len(v[1]) != 8 * n:
        raise MessageError(f"{fld}: {len(v[1])} bytes for shape {shp}")
    a = np.frombuffer(v[1], dtype="<f8").reshape(shp)
    # Plain-Python check for the small arrays that are most messages (≈10x faster than numpy there).
    if n <= 32:
        _check_values(a.ravel().tolist(), fld)
    elif n and not np.abs(a).max() <= MAX_ABS:  # False for NaN too
        raise MessageError(f"{fld}: {'non-finite values' if not np.isfinite(a).all() else f'values beyond ±{MAX_ABS:g}'}")
    return a


def _check_values(xs: list[float], fld: str) -> None:
    """Every number of ``xs`` finite and within ±MAX_ABS (raises MessageError)."""
    if not all(map(math.isfinite, xs)):
        raise MessageError(f"{fld}: non-finite values")
    if xs and (max(xs) > MAX_ABS or min(xs) < -MAX_ABS):
        raise MessageError(f"{fld}: values beyond ±{MAX_ABS:g}")


def _dec_value(v: Any, k: str) -> float | np.ndarray:
    """A named value (see OPEN): a finite number, or a float64 array of at most 4 dimensions."""
    if type(v) is float or type(v) is int:
        if not _finite(v):
            raise MessageError(f"{k}: expected a finite number within ±{MAX_ABS:g}")
        return float(v)
    if not (type(v) is list and len(v) == 2 and type(v[0]) is list and len(v[0]) <= 4):
        raise MessageError(f"{k}: expected a number or [shape, bytes]")
    shape = v[0]
    if not all(type(d) is int and 0 <= d <= MAX_VALUE_LEN for d in shape) or math.prod(shape) > MAX_VALUE_LEN:
        raise MessageError(f"{k}: bad shape {shape}")
    return _dec_arr(v, tuple(shape), k)


def _fields(v: Any, k: str) -> dict[str, float | np.ndarray]:
    if type(v) is not dict or len(v) > MAX_OPEN or not all(type(n) is str and len(n) <= 64 for n in v):
        raise MessageError(f"{k}: expected a map of at most {MAX_OPEN} names to values")
    return {n: _dec_value(x, f"{k}.{n}") for n, x in v.items()}


def _finite(x: Any) -> TypeGuard[int | float]:
    """A number (not a bool), finite and within ±MAX_ABS."""
    return not isinstance(x, bool) and isinstance(x, (int, float)) and -MAX_ABS <= x <= MAX_ABS


def _id(j: Any) -> bool:
    return type(j) is int and 0 <= j <= MAX_ID


def _kind_handler(kind: Any) -> Callable[[Any, str], Any]:
    """The validator/converter of one field kind (see SCHEMAS)."""
    if isinstance(kind, tuple):
        shape = kind
        return lambda v, k: _dec_arr(v, shape, k)
    if kind == "fields":
        return _fields
    if kind in ("vecmap", "matmap"):
        shape = (3,) if kind == "vecmap" else (3, 3)
        what = "vector" if kind == "vecmap" else "3x3 matrix"

        def arrmap(v: Any, k: str) -> dict[int, np.ndarray]:
            if type(v) is not dict or len(v) > MAX_IDS or not all(map(_id, v)):
                raise MessageError(f"{k}: expected a map of at most {MAX_IDS} ids to {what}")
            d = {}
            for j, x in v.items():
                try:
                    d[j] = _dec_arr(x, shape, k)
                except MessageError as exc:  # name the entry (built only on error)
                    raise MessageError(str(exc).replace(f"{k}:", f"{k}[{j}]:", 1)) from None
            return d

        return arrmap
    if kind == "floatmap":

        def floatmap(v: Any, k: str) -> dict[int, float]:
            if type(v) is not dict or len(v) > MAX_IDS or not all(_id(j) and _finite(x) for j, x in v.items()):
                raise MessageError(f"{k}: expected a map of at most {MAX_IDS} ids to finite numbers")
            return {j: float(x) for j, x in v.items()}

        return floatmap
    if kind == "jumps":

        def jumps(v: Any, k: str) -> list[tuple[int, float, float, float]]:
            if type(v) is not list or len(v) > MAX_IDS or not all(type(e) is list and len(e) == 4 and _id(e[0]) and all(_finite(x) for x in e[1:]) for e in v):
                raise MessageError(f"{k}: expected a list of at most {MAX_IDS} [edge, t, xi_before, xi_after]")
            return [(e[0], float(e[1]), float(e[2]), float(e[3])) for e in v]

        return jumps
    if kind == "float":

        def flt(v: Any, k: str) -> float:
            if not _finite(v):
                raise MessageError(f"{k}: expected a finite number within ±{MAX_ABS:g}")
            return float(v)

        return flt
    if kind == "int":

        def integer(v: Any, k: str) -> int:
            if type(v) is not int:
                raise MessageError(f"{k}: expected an integer")
            return v

        return integer
    if kind == "str":

        def string(v: Any, k: str) -> str:
            if type(v) is not str or len(v) > MAX_STR:
                raise MessageError(f"{k}: expected a string of at most {MAX_STR} characters")
            return v

        return string
    if kind == "intlist":

        def intlist(v: Any, k: str) -> list[int]:
            if type(v) is not list or len(v) > MAX_IDS or not all(map(_id, v)):
                raise MessageError(f"{k}: expected a list of at most {MAX_IDS} ids")
            return v

        return intlist
    if kind == "counters":
        return _counters
    raise AssertionError(f"unknown field kind {kind!r}")


# A process's counters (stats): what a receiver accepts.  ``counters = 5`` used to pass as
# "any" and make the report raise TypeError after the run.
MAX_COUNTER_DEPTH = 6
MAX_COUNTER_ITEMS = 20000


def _counters(v: Any, k: str) -> dict[str, Any]:
    if type(v) is not dict:
        raise MessageError(f"{k}: expected a map of names to counters")
    left = [MAX_COUNTER_ITEMS]

    def check(x: Any, where: str, depth: int) -> None:
        left[0] -= 1
        if left[0] < 0:
            raise MessageError(f"{k}: more than {MAX_COUNTER_ITEMS} entries")
        if depth > MAX_COUNTER_DEPTH:
            raise MessageError(f"{where}: nested deeper than {MAX_COUNTER_DEPTH}")
        t = type(x)
        if t is dict:
            for n, y in x.items():
                if type(n) is not str or len(n) > 256:
                    raise MessageError(f"{where}: keys must be names (strings of at most 256 characters)")
                check(y, f"{where}.{n}", depth + 1)
        elif t is list:
            for i, y in enumerate(x):
                check(y, f"{where}[{i}]", depth + 1)
        elif x is not None and t not in (int, float, str, bool):
            raise MessageError(f"{where}: expected a number, a string, a list or a map")
        elif t is str and len(x) > MAX_STR:
            raise MessageError(f"{where}: a string of more than {MAX_STR} characters")
        elif t is float and not math.isfinite(x):
            raise MessageError(f"{where}: not finite")

    check(v, k, 0)
    return v


# Per message type: (field, handler, optional), in schema order.
_FIELDS = {t: tuple((k, _kind_handler(kind), k in OPTIONAL.get(t, ())) for k, kind in schema.items()) for t, schema in SCHEMAS.items()}
_MISSING = object()


def _arr(a: np.ndarray) -> list[Any]:
    if type(a) is not np.ndarray or a.dtype != _F8 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype="<f8")
    return [list(a.shape), a.tobytes()]


class _Slow(Exception):
    """The fast path is not sure of decode()'s result: decode() decides."""
