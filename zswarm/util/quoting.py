"""User text inside a one-line message (``file: field: problem``).

A key, a value, a file name or a flag a user wrote can hold a newline, a tab or a
terminal escape (``\\x1b[2J`` clears the screen).  Echoed as it is, it breaks the
one-line promise of every error and can paint the user's terminal.  Every message
that quotes what a user wrote goes through :func:`shown` (or :func:`toml_key` for a
field path); :func:`one_line` is the last guard where a message leaves a process.
"""

from __future__ import annotations

import re

# TOML's (and JSON's) short escapes; any other character that is not printable
# becomes \\uXXXX or \\UXXXXXXXX, which TOML basic strings read back.
_SHORT = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}
_BARE_KEY = re.compile(r"[A-Za-z0-9_]+")


def _escape(c: str) -> str:
    if c in _SHORT:
        return _SHORT[c]
    if c.isprintable():
        return c
    n = ord(c)
    return f"\\u{n:04X}" if n < 0x10000 else f"\\U{n:08X}"


def quoted(text: str) -> str:
    """``text`` as a TOML basic string: double quotes, every non-printable character escaped."""
    return '"' + "".join(_escape(c) for c in text) + '"'


def shown(text: str) -> str:
    """``text`` itself when every character is printable, else :func:`quoted` (so a
    quote in the message says the text was escaped, and a path stays copyable)."""
    return text if text.isprintable() else quoted(text)


def toml_key(key: str) -> str:
    """One segment of a field path: bare (``seed``) or quoted (``"1->3"``, ``"a\\nb"``)."""
    return key if _BARE_KEY.fullmatch(key) else quoted(key)


def one_line(message: str) -> str:
    """``message`` with every non-printable character escaped in place: the guard at the
    exits (``error: …`` on stderr), for text that reached a message unquoted."""
    return message if message.isprintable() else "".join(c if c.isprintable() else _escape(c) for c in message)


def did_you_mean(word: object, choices: object) -> str:
    """``"; did you mean 'delay_ms'?"`` when one of ``choices`` is close to what the user wrote
    (difflib's ratio ≥ 0.7, the closest: "sinn" finds "sin", "inf" does not), else "": the tail of an "unknown key" or "must be one
    of" message (``links.dealy_ms``)."""
    import difflib

    if not isinstance(word, str):
        return ""
    close = difflib.get_close_matches(word, [str(c) for c in choices], n=1, cutoff=0.7)  # type: ignore[attr-defined]
    return f"; did you mean {close[0]!r}?" if close and close[0] != word else ""
