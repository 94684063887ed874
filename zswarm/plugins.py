"""Names -> module paths from the entry points of installed packages (algorithms, report families).

zswarm registers its own algorithms and report families in ``pyproject.toml`` exactly as a
user's package registers its own; a name can also be a module path.
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Mapping
from types import MappingProxyType


def registered(group: str, own_prefix: str) -> Mapping[str, str]:
    """Names -> module paths of the entry points of ``group``.  zswarm's own (module paths
    starting with ``own_prefix``) cannot be taken over by another package; otherwise the
    first declaration of a name wins (importlib.metadata's order)."""
    eps = importlib.metadata.entry_points(group=group)
    out: dict[str, str] = {}
    for ep in sorted(eps, key=lambda ep: not ep.value.startswith(own_prefix)):
        out.setdefault(ep.name, ep.value.split(":")[0])
    return MappingProxyType(out)
