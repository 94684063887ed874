"""The scenario file's typed schema, and the translator of its errors.

Each subsystem declares the table it owns as a :class:`Table` (a msgspec Struct that
refuses unknown keys): :class:`zswarm.scenario.clock.ClockSpec`, :class:`zswarm.scenario.links.LinkTable`,
:class:`zswarm.scenario.world_config.WorldTable` and :class:`~zswarm.scenario.world_config.CommandPolicy`,
:class:`zswarm.scenario.algorithm.StalePolicy`, the scenario's own header and noise tables.  A
number's bounds are declared beside its field, ``Annotated[float, bounds(positive=True)]``, a choice of words with
``Literal[...]``.  :func:`convert` decodes a TOML table into its type in one
``msgspec.convert`` call; when msgspec refuses it, the translator finds the field its error
points at (msgspec's ``$.a.b[0]`` path) and words the problem as the loader always has —
``file: field: problem (got X)``, or ``--set …: field: problem`` — from the field's declared
type and the value in the file, so one declaration decides both what is accepted and what
the user reads.

What a type cannot say stays a hand-written check beside the conversion: bounds that
depend on another field (a clock's jitter under half its period), rotations, expressions,
the papers' assumptions on graphs (Assumption 4.2, Condition 4.1/5.1) with their equation
numbers.
"""

from __future__ import annotations

import math
import re
import sys
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal, TypeVar, Union

import msgspec

from zswarm.util.quoting import did_you_mean

if typing.TYPE_CHECKING:
    from zswarm.scenario.reading import ScenarioError, _Ctx

FMAX = sys.float_info.max  # -FMAX <= x <= FMAX: finite (nan fails every comparison)
T = TypeVar("T")


class Table(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A table of the scenario file: unknown keys refused, fields keyword-only."""


@dataclass(frozen=True, slots=True)
class Bounds:
    """A number's declared bounds, and the words for each (those of ``_Ctx.num``, in its order:
    a number, finite, > 0, >= 0, <= maxv, >= minv, within ±within)."""

    positive: bool = False
    nonneg: bool = False
    maxv: float | None = None
    minv: float | None = None
    within: float | None = None  # |x| <= within (< within when within_open)
    within_open: bool = False
    unit: str = ""  # after the bound of "within": " s", " ppm"
    why: str = ""  # after the bound of "<= maxv" and "within", in parentheses
    problem_text: str = ""  # one wording for the whole range (a probability)
    got_float: bool = False  # the message shows the value as a float (the links' always have)

    def _lower(self) -> tuple[float, bool]:
        """The tightest lower bound, and whether it is strict."""
        cands = [(-FMAX, False)]
        cands += [(0.0, True)] if self.positive else []
        cands += [(0.0, False)] if self.nonneg else []
        cands += [(self.minv, False)] if self.minv is not None else []
        cands += [(-self.within, self.within_open)] if self.within is not None else []
        return max(cands)  # at a tie the strict one (True > False)

    def _upper(self) -> tuple[float, bool]:
        cands = [(FMAX, False)]
        cands += [(self.maxv, False)] if self.maxv is not None else []
        cands += [(self.within, self.within_open)] if self.within is not None else []
        return min(cands, key=lambda b: (b[0], not b[1]))

    def problem(self, v: Any) -> str | None:
        """What is wrong with ``v``, worded as the loader words it; None when nothing is."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return "must be a number"
        x = float(v)
        if not math.isfinite(x):
            return "must be finite"
        why = f" ({self.why})" if self.why else ""
        if self.problem_text and not self._inside(x):
            return self.problem_text
        if self.positive and x <= 0:
            return "must be > 0"
        if self.nonneg and x < 0:
            return "must be >= 0"
        if self.maxv is not None and x > self.maxv:
            return f"must be <= {self.maxv:g}{why}"
        if self.minv is not None and x < self.minv:
            return f"must be >= {self.minv:g}"
        if self.within is not None and (abs(x) >= self.within if self.within_open else abs(x) > self.within):
            return f"must be within ±{self.within:g}{self.unit}{why}"
        return None

    def _inside(self, x: float) -> bool:
        (lo, lo_strict), (hi, hi_strict) = self._lower(), self._upper()
        return (x > lo if lo_strict else x >= lo) and (x < hi if hi_strict else x <= hi)


def bounds(**declared: Any) -> msgspec.Meta:
    """A number's bounds for its field's ``Annotated[float, bounds(...)]`` (:class:`Bounds`'
    fields): msgspec checks them, the translator words them (it finds the Bounds in ``extra``)."""
    b = Bounds(**declared)
    (lo, lo_strict), (hi, hi_strict) = b._lower(), b._upper()
    kw: dict[str, Any] = {"gt" if lo_strict else "ge": lo, "lt" if hi_strict else "le": hi}
    return msgspec.Meta(**kw, extra={"zswarm.bounds": b})


def convert(c: _Ctx, d: Any, fld: str, typ: type[T], defaults: Mapping[str, Any] | None = None) -> T:
    """Table ``d`` (at ``fld``) as ``typ``; ``defaults`` fill the keys ``d`` leaves out (a
    default that depends on the algorithm, or a base table a more specific one overrides).
    Every problem is one :class:`ScenarioError` worded as ``_Ctx`` words it."""
    if defaults and isinstance(d, dict):
        d = {**defaults, **d}
    try:
        return msgspec.convert(d, typ, strict=True)
    except msgspec.ValidationError as exc:
        raise _translate(c, d, fld, typ, str(exc)) from None


_AT = re.compile(r" - at `\$(?P<path>[^`]*)`$")
_STEP = re.compile(r"\.(?P<name>[A-Za-z_][A-Za-z0-9_]*)|\[(?P<index>\d+)\]")
_PATH = re.compile(r"(?:\.[A-Za-z_][A-Za-z0-9_]*|\[\d+\])*")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<name>.*)`$", re.DOTALL)
_MISSING = re.compile(r"^Object missing required field `(?P<name>.*)`$", re.DOTALL)


def _translate(c: _Ctx, d: Any, fld: str, typ: Any, message: str) -> ScenarioError:
    from zswarm.util.quoting import toml_key

    # msgspec ends the message with the path, except at the top ("- at `$...`" then is part
    # of a key it quotes, a key the user wrote): a reading whose path is not in the document,
    # or whose unknown key is not there, is not the one.
    m = _AT.search(message)
    for head, path in ((message[: m.start()], m["path"]), (message, "")) if m else ((message, ""),):
        found = _walk(typ, d, fld, path)
        if found is None:
            continue
        typ_, value, name = found
        if u := _UNKNOWN.match(head):
            if not (isinstance(value, dict) and u["name"] in value and u["name"] not in _fields(typ_)):
                continue
            return c.err(_join(name, toml_key(u["name"])), f"unknown key{did_you_mean(u['name'], _fields(typ_))} (allowed: {', '.join(sorted(_fields(typ_)))})")
        if u := _MISSING.match(head):
            return c.err(_join(name, u["name"]), "missing")
        problem, bounds = _problem(typ_, value)
        got = float(value) if bounds is not None and bounds.got_float and problem not in ("must be a number", None) else value
        return c.err(name, problem or head, got)
    return c.err(fld, message, d)


def _walk(typ: Any, value: Any, name: str, path: str) -> tuple[Any, Any, str] | None:
    """The declared type, the value in the document and the field name at msgspec's ``path``;
    None when the document has no such place."""
    if not _PATH.fullmatch(path):
        return None
    for step in _STEP.finditer(path):
        if step["name"] is not None:
            key = step["name"]
            fields = _fields(typ)
            if key not in fields or not isinstance(value, dict) or key not in value:
                return None
            typ, value, name = fields[key], value[key], _join(name, key)
        else:
            k = int(step["index"])
            if not isinstance(value, list) or k >= len(value):
                return None
            typ, value, name = _element(typ, k), value[k], f"{name}[{k}]"
    return typ, value, name


def _join(name: str, key: str) -> str:
    return f"{name}.{key}" if name else key


def _unwrap(typ: Any) -> tuple[Any, Bounds | None]:
    """The type under Annotated and ``| UnsetType``, and its declared bounds."""
    bounds = None
    while True:
        origin = typing.get_origin(typ)
        if origin is Annotated:
            args = typing.get_args(typ)
            bounds = next((a.extra["zswarm.bounds"] for a in args[1:] if isinstance(a, msgspec.Meta) and a.extra and "zswarm.bounds" in a.extra), bounds)
            typ = args[0]
        elif origin is Union or type(typ).__name__ == "UnionType":
            rest = [a for a in typing.get_args(typ) if a is not msgspec.UnsetType and a is not type(None)]
            if len(rest) != 1:
                return typ, bounds
            typ = rest[0]
        else:
            return typ, bounds


def _fields(typ: Any) -> dict[str, Any]:
    t, _ = _unwrap(typ)
    return dict(typing.get_type_hints(t, include_extras=True)) if isinstance(t, type) and issubclass(t, msgspec.Struct) else {}


def _element(typ: Any, k: int) -> Any:
    t, _ = _unwrap(typ)
    args = typing.get_args(t)
    if typing.get_origin(t) is tuple and args and args[-1] is not Ellipsis:
        return args[k]
    return args[0] if args else Any


def _problem(typ: Any, v: Any) -> tuple[str | None, Bounds | None]:
    t, bounds = _unwrap(typ)
    if bounds is not None:
        return bounds.problem(v), bounds
    if (isinstance(t, type) and issubclass(t, msgspec.Struct)) or typing.get_origin(t) is dict:
        return "must be a table", None
    if typing.get_origin(t) is Literal:
        return ("must be a string" if not isinstance(v, str) else f"must be one of {', '.join(typing.get_args(t))}{did_you_mean(v, typing.get_args(t))}"), None
    if t is bool:
        return "must be true or false", None
    if t is int:
        return "must be an integer", None
    if t is str:
        return "must be a string", None
    return None, None
