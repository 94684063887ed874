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


# zswarm sim hosts the agent and world programs' own classes in one process, found here like an
# algorithm: by name in the entry-point group PROCESS_GROUP (agent/ and world/ register theirs
# in pyproject.toml), so that nothing under zswarm/ imports those programs.
PROCESS_GROUP = "zswarm.processes"
OWN_PROCESSES = {"agent": "agent.", "world": "world."}


def process_class(name: str) -> type:
    """The class of the process ``name`` ("agent": AgentNode, "world": World)."""
    import importlib

    target = registered(PROCESS_GROUP, OWN_PROCESSES[name]).get(name)
    if target is None:
        raise RuntimeError(f"no {name!r} process registered in the entry points {PROCESS_GROUP!r} (zswarm is not installed: pip install -e .)")
    ep = next(e for e in importlib.metadata.entry_points(group=PROCESS_GROUP) if e.name == name and e.value.split(":")[0] == target)
    cls = ep.load()
    assert isinstance(cls, type)
    return cls
