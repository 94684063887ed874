"""Command-line overrides of a scenario: ``--set FIELD=VALUE`` (and ``--fault``, ``--vary``),
parsed, applied to the TOML document before it is read, and rendered back."""

from __future__ import annotations

import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from zswarm.scenario.reading import ScenarioError
from zswarm.util.quoting import shown, toml_key


@dataclass(frozen=True, slots=True)
class Override:
    """One ``--set FIELD=VALUE``: ``keys`` is the path into the TOML document
    (table keys and array indices), ``field`` its canonical spelling."""

    flag: str  # as given, e.g. "--set links.delay_ms=50"
    field: str  # e.g. 'links.per_link."1->3".drop', "agents[2].clock.rate"
    keys: tuple[str | int, ...]
    value: Any

    @property
    def label(self) -> str:
        """``flag`` for a one-line message: the user's text escaped when it holds a newline, a tab, …"""
        name, _, text = self.flag.partition(" ")
        return f"{name} {shown(text)}"


_SEGMENT = re.compile(r'"(?P<q>[^"]*)"|(?P<k>[A-Za-z0-9_>-]+)|\[(?P<i>\d+)\]')


def _field_name(keys: Sequence[str | int]) -> str:
    out = ""
    for k in keys:
        if isinstance(k, int):
            out += f"[{k}]"
        else:
            part = toml_key(k)
            out += f".{part}" if out else part
    return out


def parse_field(text: str, flag: str = "--set") -> tuple[str | int, ...]:
    """``links.per_link."1->3".drop`` or ``agents[2].clock.rate`` -> the key path."""
    keys: list[str | int] = []
    pos = 0
    while pos < len(text):
        if keys and not text.startswith("[", pos):
            if not text.startswith(".", pos):
                raise ScenarioError(f"{flag}: {shown(text)}: cannot parse the field name at {text[pos:]!r}")
            pos += 1
        m = _SEGMENT.match(text, pos)
        if m is None or m.end() == pos:
            raise ScenarioError(f"{flag}: {shown(text)}: cannot parse the field name at {text[pos:]!r}")
        keys.append(int(m["i"]) if m["i"] is not None else (m["q"] if m["q"] is not None else m["k"]))
        pos = m.end()
    if not keys or isinstance(keys[0], int):
        raise ScenarioError(f"{flag}: {text!r}: expected FIELD=VALUE, e.g. links.delay_ms=50")
    return tuple(keys)


def parse_value(raw: str) -> Any:
    """A TOML value (``50``, ``0.3``, ``true``, ``[1, 0, 0]``, ``"0.1*pi"``); anything
    that is not valid TOML is taken as a string (``exponential``)."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def parse_override(text: str, flag: str = "--set") -> Override:
    """``FIELD=VALUE`` as given to ``--set`` (or one value of ``--vary``)."""
    name, eq, raw = text.partition("=")
    if not eq or not name.strip():
        raise ScenarioError(f"{flag}: {text!r}: expected FIELD=VALUE, e.g. links.delay_ms=50")
    keys = parse_field(name.strip(), flag)
    return Override(f"{flag} {text}", _field_name(keys), keys, parse_value(raw.strip()))


def _apply(doc: dict[str, Any], o: Override) -> None:
    node: Any = doc
    for n, k in enumerate(o.keys[:-1]):
        here = _field_name(o.keys[: n + 1])
        nxt = o.keys[n + 1]
        if isinstance(k, int):
            if not isinstance(node, list):
                raise ScenarioError(f"{o.label}: {here}: not an array")
            if not 0 <= k < len(node):
                raise ScenarioError(f"{o.label}: {here}: no such element (the array has {len(node)})")
            node = node[k]
        else:
            if not isinstance(node, dict):
                raise ScenarioError(f"{o.label}: {here}: not a table")
            if k not in node:
                node[k] = [] if isinstance(nxt, int) else {}
            node = node[k]
    last = o.keys[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or not 0 <= last < len(node):
            raise ScenarioError(f"{o.label}: {o.field}: no such element")
        node[last] = o.value
    elif not isinstance(node, dict):
        raise ScenarioError(f"{o.label}: {_field_name(o.keys[:-1])}: not a table")
    else:
        node[last] = o.value


def render(doc: dict[str, Any], source: str, overrides: Sequence[Override]) -> str:
    """The TOML text of a scenario with overrides applied (comments are not kept)."""
    import tomli_w

    head = f"# {shown(source)}, with " + ", ".join(o.label for o in overrides) + "\n" if overrides else ""
    return head + tomli_w.dumps(doc)
