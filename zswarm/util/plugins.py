"""Names -> module paths from the entry points of installed packages (algorithms, report families).

zswarm registers its own algorithms and report families in ``pyproject.toml`` exactly as a
user's package registers its own; a name can also be a module path.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
from collections.abc import Mapping
from types import MappingProxyType, ModuleType


def _ranked(group: str, own_prefix: str) -> list[importlib.metadata.EntryPoint]:
    """The entry points of ``group``, zswarm's own (values starting with ``own_prefix``) first."""
    return sorted(importlib.metadata.entry_points(group=group), key=lambda ep: not ep.value.startswith(own_prefix))


@functools.cache  # the installed packages do not change under a process; a scan costs ~1.4 ms, a load made 3
def registered(group: str, own_prefix: str) -> Mapping[str, str]:
    """Names -> module paths of the entry points of ``group``.  zswarm's own (module paths
    starting with ``own_prefix``) cannot be taken over by another package; otherwise the
    first declaration of a name wins (importlib.metadata's order)."""
    out: dict[str, str] = {}
    for ep in _ranked(group, own_prefix):
        out.setdefault(ep.name, ep.value.split(":")[0])
    return MappingProxyType(out)


# zswarm sim hosts the agent and world programs' own classes in one process, found here like an
# algorithm: by name in the entry-point group PROCESS_GROUP (agent/ and world/ register theirs
# in pyproject.toml), so that nothing under zswarm/ imports those programs.
PROCESS_GROUP = "zswarm.processes"
OWN_PROCESSES = {"agent": "agent.", "world": "world.", "batched": "agent."}


def _load(name: str) -> object:
    """What is registered as ``name`` in PROCESS_GROUP, zswarm's own first."""
    ep = next((e for e in _ranked(PROCESS_GROUP, OWN_PROCESSES[name]) if e.name == name), None)
    if ep is None:
        raise RuntimeError(f"no {name!r} registered in the entry points {PROCESS_GROUP!r} (zswarm is not installed: pip install -e .)")
    return ep.load()


def engine(name: str) -> ModuleType:
    """The module registered as ``name`` in PROCESS_GROUP ("batched": the batched lockstep
    engine, agent/batched.py)."""
    mod = _load(name)
    assert isinstance(mod, ModuleType)
    return mod


def process_class(name: str) -> type:
    """The class of the process ``name`` ("agent": AgentNode, "world": World)."""
    cls = _load(name)
    assert isinstance(cls, type)
    return cls


# The experiment families (zswarm.families.contract), found by the name an algorithm's SPEC.report gives.
FAMILY_GROUP = "zswarm.families"
OWN_FAMILIES = "zswarm.families."  # zswarm's own (registered in pyproject.toml)


def family_module(name: str) -> str | None:
    """The module path of the experiment family ``name`` (registered, or a module path that can
    be imported), without importing it; None when there is none."""
    target = registered(FAMILY_GROUP, OWN_FAMILIES).get(name, name)
    try:
        found = importlib.util.find_spec(target)
    except (ImportError, ValueError):
        return None
    return target if found is not None else None
