"""Whitelisted arithmetic expressions in ``t`` for prescribed motions.

Grammar (recursive descent, precedence low to high)::

    expr    := term (('+' | '-') term)*
    term    := unary (('*' | '/') unary)*
    unary   := ('+' | '-') unary | power
    power   := atom ('**' unary)?          # right-associative, binds tighter than unary minus on its left
    atom    := NUMBER | 't' | 'pi' | FUNC '(' expr ')' | '(' expr ')'
    FUNC    := sin | cos | tan | exp | sqrt | abs

Nothing else is accepted; Python's ``eval``/``compile`` are never used.  A
parsed expression is a tree of closures that works on floats and on numpy
arrays of times alike (the world evaluates many sub-steps in one call).
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from zswarm.util.quoting import did_you_mean

Number = float | np.ndarray
Fn = Callable[[Number], Number]

FUNCTIONS: dict[str, Callable[[Number], Number]] = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "exp": np.exp,
    "sqrt": np.sqrt,
    "abs": np.abs,
}
CONSTANTS = {"pi": math.pi}

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_]\w*)|(?P<op>\*\*|[-+*/()]))"
)


class ExprError(ValueError):
    """An expression that the whitelist does not accept."""


# Nesting allowed (parentheses, function calls, unary signs, exponents, each one level): a
# motion never needs more, and the parser and the closures it builds recurse once per
# level, so 2000 nested parentheses used to end in RecursionError.  Sums and products
# of any length are one level (evaluated in a loop, left to right as before).
MAX_DEPTH = 64
MAX_TOKENS = 20000


@dataclass(frozen=True, slots=True)
class Expr:
    """A parsed expression in ``t``; call it with a float or an array of times."""

    source: str
    fn: Fn = field(repr=False, compare=False)
    constant: bool = field(default=False, compare=False)

    def __call__(self, t: Number) -> Number:
        return self.fn(t)


def _tokens(src: str) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    pos = 0
    src = src.rstrip()
    while pos < len(src):
        m = _TOKEN.match(src, pos)
        if m is None or m.end() == pos:
            raise ExprError(f"unexpected character {src[pos:].lstrip()[:1]!r} at position {pos}")
        kind = m.lastgroup
        assert kind is not None
        out.append((kind, m.group(kind)))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, src: str) -> None:
        self.toks = _tokens(src)
        if len(self.toks) > MAX_TOKENS:
            raise ExprError(f"too long ({len(self.toks)} tokens, at most {MAX_TOKENS})")
        self.i = 0
        self.depth = 0

    def peek(self) -> tuple[str, str] | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def take(self) -> tuple[str, str]:
        tok = self.peek()
        if tok is None:
            raise ExprError("unexpected end of expression")
        self.i += 1
        return tok

    def expect(self, op: str) -> None:
        tok = self.take()
        if tok != ("op", op):
            raise ExprError(f"expected {op!r}, got {tok[1]!r}")

    # Each parse_* returns (closure, is_constant).
    def parse_expr(self) -> tuple[Fn, bool]:
        f, c = self.parse_term()
        rest: list[tuple[str, Fn]] = []
        while (tok := self.peek()) in (("op", "+"), ("op", "-")):
            self.take()
            g, d = self.parse_term()
            rest.append((tok[1], g))  # type: ignore[index]
            c = c and d
        return _chain(f, rest), c

    def parse_term(self) -> tuple[Fn, bool]:
        f, c = self.parse_unary()
        rest: list[tuple[str, Fn]] = []
        while (tok := self.peek()) in (("op", "*"), ("op", "/")):
            self.take()
            g, d = self.parse_unary()
            rest.append((tok[1], g))  # type: ignore[index]
            c = c and d
        return _chain(f, rest), c

    def parse_unary(self) -> tuple[Fn, bool]:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExprError(f"nested too deeply (more than {MAX_DEPTH} levels of parentheses, calls, signs or powers)")
        try:
            tok = self.peek()
            if tok == ("op", "-"):
                self.take()
                f, c = self.parse_unary()
                return (lambda t, f=f: -f(t)), c
            if tok == ("op", "+"):
                self.take()
                return self.parse_unary()
            return self.parse_power()
        finally:
            self.depth -= 1

    def parse_power(self) -> tuple[Fn, bool]:
        f, c = self.parse_atom()
        if self.peek() == ("op", "**"):
            self.take()
            g, d = self.parse_unary()
            return _bin(f, g, "**"), c and d
        return f, c

    def parse_atom(self) -> tuple[Fn, bool]:
        kind, text = self.take()
        if kind == "num":
            v = float(text)
            return (lambda t, v=v: v), True
        if kind == "name":
            if text == "t":
                return (lambda t: t), False
            if text in CONSTANTS:
                v = CONSTANTS[text]
                return (lambda t, v=v: v), True
            if text in FUNCTIONS:
                fn = FUNCTIONS[text]
                self.expect("(")
                f, c = self.parse_expr()
                self.expect(")")
                return (lambda t, fn=fn, f=f: fn(f(t))), c
            allowed = ", ".join(["t", *CONSTANTS, *FUNCTIONS])
            raise ExprError(f"unknown name {text!r}{did_you_mean(text, ['t', *CONSTANTS, *FUNCTIONS])} (allowed: {allowed})")
        if text == "(":
            f, c = self.parse_expr()
            self.expect(")")
            return f, c
        raise ExprError(f"unexpected {text!r}")


_OPS: dict[str, Callable[[Number, Number], Number]] = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": lambda a, b: a * b,
    "/": lambda a, b: a / b,
}


def _chain(f: Fn, rest: list[tuple[str, Fn]]) -> Fn:
    """``f op g op h ...`` evaluated left to right in one closure (one level deep however
    long the chain: a 3000-term sum used to be 3000 nested closures)."""
    if not rest:
        return f
    if len(rest) == 1:
        op, g = rest[0]
        fn = _OPS[op]
        return lambda t: fn(f(t), g(t))
    steps = tuple((_OPS[op], g) for op, g in rest)

    def chain(t: Number) -> Number:
        acc = f(t)
        for fn, g in steps:
            acc = fn(acc, g(t))
        return acc

    return chain


def _power(a: Number, b: Number) -> Number:
    """``a ** b`` as numpy computes it for floats and arrays alike: a negative base with a
    non-integer exponent is NaN (caught as "not finite"), where Python's float power
    returned a complex number that escaped as TypeError."""
    return np.power(a, b)


def _bin(f: Fn, g: Fn, op: str) -> Fn:
    assert op == "**"
    return lambda t: _power(f(t), g(t))


def parse(src: str | int | float) -> Expr:
    """Parse ``src`` (a string, or a plain number) into an :class:`Expr`.

    Raises
    ------
    ExprError
        When ``src`` uses anything outside the whitelist, or does not
        evaluate to a finite number at ``t = 0``.
    """
    if isinstance(src, bool) or not isinstance(src, (str, int, float)):
        raise ExprError(f"expected an expression string or a number, got {type(src).__name__}")
    return _parse(str(src))


@functools.lru_cache(maxsize=4096)
def _parse(text: str) -> Expr:
    """:func:`parse` of a text, remembered (an Expr is immutable; a basin's draws read the same
    motions once a draw).  An ExprError is raised again on every call."""
    p = _Parser(text)
    if not p.toks:
        raise ExprError("empty expression")
    fn, const = p.parse_expr()
    if p.i != len(p.toks):
        raise ExprError(f"unexpected {p.toks[p.i][1]!r} after a complete expression")
    with np.errstate(all="ignore"):
        try:
            v0 = float(fn(0.0))
        except (ZeroDivisionError, OverflowError, ValueError, TypeError) as exc:
            raise ExprError(f"cannot be evaluated at t = 0 ({exc})") from None
    if not math.isfinite(v0):
        raise ExprError("is not finite at t = 0")
    if const:
        return Expr(text, lambda t, v=v0: v + 0.0 * t if isinstance(t, np.ndarray) else v, True)
    return Expr(text, fn, False)
