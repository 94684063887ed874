"""The world's plants as a scenario configures them (``[world] plant``, ``[world.commands]``,
``[world] sensors``, an agent's inertia ``J``); world/plant.py implements them."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from zswarm.algorithm import AlgorithmSpec
from zswarm.reader import _Ctx

# The world's plants and command policy (world/plant.py); imported lazily there to keep
# the loader free of the world package's numerics.
PLANTS = ("prescribed", "rigid_body", "kinematic")


PLANT_INPUTS: Mapping[str, Mapping[str, tuple[int, ...]]] = MappingProxyType(
    {"prescribed": {}, "rigid_body": {"tau": (3,)}, "kinematic": {"vel": (3,), "yaw_rate": ()}}
)


COMMAND_POLICIES = ("zero", "hold")


@dataclass(frozen=True, slots=True)
class CommandPolicy:
    """``[world.commands]``: how old a command may be, and what happens past that age (world/plant.py)."""

    max_age: float = 0.5  # s
    policy: str = "zero"


def _plant(c: _Ctx, w: dict[str, Any], info: AlgorithmSpec, algo: str, formation: bool) -> tuple[str, CommandPolicy, frozenset[str] | None]:
    """``[world] plant``, ``[world.commands]`` and ``[world] sensors``, checked against what the
    algorithm sends (SPEC.command) and measures (SPEC.sensors)."""
    from zswarm.algorithm import SENSORS

    sends = {k: f.shape for k, f in info.command.items()}
    default = next((p for p in PLANTS if sends and dict(PLANT_INPUTS[p]) == sends), "prescribed")
    plant = c.string(w.get("plant", default), "world.plant")
    if plant not in PLANTS:
        raise c.err("world.plant", f"must be one of {', '.join(PLANTS)}", plant)
    reads = dict(PLANT_INPUTS[plant])
    if sends and sends != reads:
        raise c.err("world.plant", f"{algo} sends {sends or 'nothing'} on cmd/<i>, but the {plant!r} plant reads {reads or 'nothing'}", plant)
    if plant != "prescribed" and formation:
        raise c.err("world.formation", f"a formation is a prescribed motion; the {plant!r} plant moves by its own dynamics")
    cm = c.table(w.get("commands", {}), "world.commands", {"max_age", "policy"})
    if cm and plant == "prescribed":
        raise c.err("world.commands", "the prescribed plant takes no commands")
    base = CommandPolicy()
    policy = CommandPolicy(
        c.num(cm.get("max_age", base.max_age), "world.commands.max_age", positive=True),
        c.string(cm.get("policy", base.policy), "world.commands.policy"),
    )
    if policy.policy not in COMMAND_POLICIES:
        raise c.err("world.commands.policy", f"must be one of {', '.join(COMMAND_POLICIES)}", policy.policy)
    fitted = None
    if "sensors" in w:
        raw = w["sensors"]
        if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
            raise c.err("world.sensors", f"must be a list of sensor names ({', '.join(SENSORS)})", raw)
        for x in raw:
            if x not in SENSORS:
                raise c.err("world.sensors", f"unknown sensor {x!r} (known: {', '.join(SENSORS)})", raw)
        fitted = frozenset(raw)
        missing = sorted(set(info.sensors) - fitted)
        if missing:
            why = "; ".join(f"{m}: {info.sensor_use.get(m, 'declared in its SPEC.sensors')}" for m in missing)
            raise c.err("world.sensors", f"{algo} needs the sensor(s) {', '.join(repr(m) for m in missing)}, not fitted ({why})", raw)
    return plant, policy, fitted


def _inertia(c: _Ctx, v: Any, fld: str) -> tuple[float, ...]:
    """An inertia matrix: 3 principal moments (diagonal) or a 3x3 list of rows, symmetric positive definite."""
    if isinstance(v, list) and len(v) == 3 and all(not isinstance(x, list) for x in v):
        J = np.diag(c.vec3(v, fld))
    elif isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3 for r in v):
        J = np.array([[c.num(e, f"{fld}[{a}][{b}]") for b, e in enumerate(r)] for a, r in enumerate(v)])
    else:
        raise c.err(fld, "must be 3 principal moments or a 3x3 list of rows (kg m^2)", v)
    if not np.allclose(J, J.T, rtol=1e-9, atol=1e-12):
        raise c.err(fld, "must be symmetric", v)
    lam = np.linalg.eigvalsh(0.5 * (J + J.T))
    if lam[0] <= 0:
        raise c.err(fld, f"must be positive definite (eigenvalues {np.round(lam, 6).tolist()})", v)
    return tuple(J.ravel().tolist())
