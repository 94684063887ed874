"""Reading a scenario file: the reader every subsystem's config parser uses.

Each subsystem owns its part of the scenario file: its config type and the parser
that reads it with a :class:`_Ctx` (``zswarm.scenario.algorithm.Reader``) — clocks
(:mod:`zswarm.scenario.clock`), links (:mod:`zswarm.scenario.links`), the world's plant
(:mod:`zswarm.scenario.world_config`), faults (:mod:`zswarm.scenario.faults`), graphs (:mod:`zswarm.scenario.graph`),
an algorithm's params (its ``SPEC.params``).  The reader checks and converts one
value at a time, bounds declared at the call beside the field, and every error it
makes reads ``file: field: problem (got X)`` (``--set ...: field: problem`` when a
command-line override is at fault).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from zswarm.math import so3
from zswarm.scenario.expr import Expr, ExprError, parse
from zswarm.scenario.schema import Bounds, convert
from zswarm.util.quoting import did_you_mean, shown, toml_key

T = TypeVar("T")


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names file, field and problem."""


class _Ctx:
    """Carries the file name so every error names file and field."""

    def __init__(self, path: str, overridden: Mapping[str, str] | None = None) -> None:
        self.path = shown(path)
        self.overridden = overridden or {}  # field path -> the flag that set it (Override.label)

    def where(self, fld: str) -> str:
        """The file, or the flag when ``fld`` (or a table holding it) was set on the command line."""
        for f, flag in self.overridden.items():
            # The field itself, inside it, or a table the override reached into (an unknown key).
            if fld == f or fld.startswith((f + ".", f + "[")) or f.startswith((fld + ".", fld + "[")):
                return flag
        return self.path

    def err(self, fld: str, problem: str, got: Any = ...) -> ScenarioError:
        tail = "" if got is ... else f" (got {got!r})"
        return ScenarioError(f"{self.where(fld)}: {fld}: {problem}{tail}")

    def table(self, d: Any, fld: str, allowed: set[str], required: set[str] = frozenset()) -> dict[str, Any]:  # type: ignore[assignment]
        if not isinstance(d, dict):
            raise self.err(fld, "must be a table", d)
        for k in d:
            if k not in allowed:
                key = toml_key(k)
                raise self.err(f"{fld}.{key}" if fld else key, f"unknown key{did_you_mean(k, allowed)} (allowed: {', '.join(sorted(allowed))})")
        for k in sorted(required):
            if k not in d:
                raise self.err(f"{fld}.{k}" if fld else k, "missing")
        return d

    def num(self, v: Any, fld: str, *, positive: bool = False, nonneg: bool = False, maxv: float | None = None, minv: float | None = None) -> float:
        """A finite number within the bounds, worded as the schema words them (zswarm.scenario.schema.Bounds)."""
        if (type(v) is float or type(v) is int) and not (positive or nonneg) and maxv is None and minv is None:
            x = float(v)
            if math.isfinite(x):  # the common case, without building a Bounds (a basin loads thousands of numbers a second)
                return x
        problem = Bounds(positive=positive, nonneg=nonneg, maxv=maxv, minv=minv).problem(v)
        if problem is not None:
            raise self.err(fld, problem, v)
        return float(v)

    def typed(self, d: Any, fld: str, typ: type[T], defaults: Mapping[str, Any] | None = None) -> T:
        """Table ``d`` as its declared type (zswarm.scenario.schema.convert): unknown keys, types and
        bounds checked by msgspec, every problem worded ``file: field: problem (got X)``."""
        return convert(self, d, fld, typ, defaults)

    def integer(self, v: Any, fld: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(fld, "must be an integer", v)
        return v

    def string(self, v: Any, fld: str) -> str:
        if not isinstance(v, str):
            raise self.err(fld, "must be a string", v)
        return v

    def vec3(self, v: Any, fld: str) -> tuple[float, float, float]:
        if not isinstance(v, list) or len(v) != 3:
            raise self.err(fld, "must be a list of 3 numbers", v)
        x, y, z = (self.num(e, f"{fld}[{k}]") for k, e in enumerate(v))
        return (x, y, z)

    def axis(self, v: Any, fld: str) -> NDArray[np.float64]:
        """A direction: the unit vector along a non-zero 3-vector.  Scaled by its largest
        entry first, so that neither [1e300, 1e300, 0] (whose norm overflows to inf, which
        made the axis 0 with a RuntimeWarning) nor [1e-200, 1e-200, 0] (whose squares
        underflow, which read as a zero axis) is mistaken."""
        x = np.array(self.vec3(v, fld))
        m = float(np.max(np.abs(x)))
        if m == 0.0:
            raise self.err(fld, "must be non-zero", v)
        x = x / m
        return x / np.linalg.norm(x)

    def expr(self, v: Any, fld: str) -> Expr:
        try:
            return parse(v)
        except ExprError as exc:
            raise self.err(fld, str(exc), v) from None

    def rotation(self, v: Any, fld: str) -> tuple[float, ...]:
        """A rotation: ``{angle = "0.1*pi", axis = [1,0,0]}`` or a 3×3 list of rows."""
        if isinstance(v, dict):
            self.table(v, fld, {"angle", "axis"}, {"angle", "axis"})
            theta = float(self.expr(v["angle"], f"{fld}.angle")(0.0))
            return tuple(so3.Ra(theta, self.axis(v["axis"], f"{fld}.axis")).ravel().tolist())
        if isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3 for r in v):
            R = [self.num(e, f"{fld}[{a}][{b}]") for a, r in enumerate(v) for b, e in enumerate(r)]
            if not _is_rotation(R, 1e-6):
                raise self.err(fld, "is not a rotation matrix (R^T R = I, det R = 1 within 1e-6)", v)
            return tuple(R)
        raise self.err(fld, "must be {angle, axis} or a 3x3 list of rows", v)


def _user_code(c: _Ctx, fld: str, call: Any) -> Any:
    """Run a params type's or an initial field's own reading code (an algorithm's, maybe a
    user's): a ScenarioError it raises stands; anything else it raises is one ``file: field:``
    line naming the exception, not a traceback."""
    try:
        return call()
    except ScenarioError:
        raise
    except Exception as exc:  # noqa: BLE001 - a user's code may raise anything
        raise c.err(fld, f"the algorithm's own check failed: {type(exc).__name__}: {exc}") from None


def _is_rotation(R: list[float], tol: float) -> bool:
    """so3.is_rotation of a 3x3 matrix given as 9 finite floats, row-major, in Python's arithmetic
    (a basin loads 14 rotations a draw; numpy's small-array calls were most of it)."""
    for i in range(3):
        for j in range(i, 3):
            d = R[i] * R[j] + R[3 + i] * R[3 + j] + R[6 + i] * R[6 + j] - (1.0 if i == j else 0.0)
            if not abs(d) <= tol:
                return False
    det = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) + R[2] * (R[3] * R[7] - R[4] * R[6])
    return abs(det - 1.0) <= tol
