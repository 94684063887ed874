"""The world as a scenario configures it: ``[world]`` (its step, sensor rate, plant, sensors,
``[world.commands]``, ``[world.formation]``), ``[noise]``, an agent's inertia ``J``; the
types of those tables (zswarm.scenario.schema), and the checks a type cannot make; world/plant.py
implements the plants."""

from __future__ import annotations

import functools
import typing
from collections.abc import Mapping
from types import MappingProxyType
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from zswarm.math.limits import MAX_ABS
from zswarm.scenario.algorithm import AlgorithmSpec
from zswarm.scenario.reading import _Ctx
from zswarm.scenario.schema import Table, bounds

# The world's plants and command policy (world/plant.py); imported lazily there to keep
# the loader free of the world package's numerics.
Plant = Literal["prescribed", "rigid_body", "kinematic"]
PLANTS: tuple[str, ...] = typing.get_args(Plant)


PLANT_INPUTS: Mapping[str, Mapping[str, tuple[int, ...]]] = MappingProxyType(
    {"prescribed": {}, "rigid_body": {"tau": (3,)}, "kinematic": {"vel": (3,), "yaw_rate": ()}}
)


Policy = Literal["zero", "hold"]
COMMAND_POLICIES: tuple[str, ...] = typing.get_args(Policy)


class CommandPolicy(Table, frozen=True, kw_only=False):
    """``[world.commands]``: how old a command may be, and what happens past that age (world/plant.py)."""

    max_age: Annotated[float, bounds(positive=True)] = 0.5  # s
    policy: Policy = "zero"


# A truth step under 1 µs is a million steps per simulated second (1e-300 never ended).
MIN_WORLD_STEP_S = 1e-6
# Noise added to a measured value: 10 σ within the wire's ±MAX_ABS (a sample beyond it is
# dropped as malformed: gyro_var = 1e30 gave 0 steps and a run that read completed).
MAX_NOISE_VAR = (0.1 * MAX_ABS) ** 2
_ADDED_NOISE = bounds(nonneg=True, maxv=MAX_NOISE_VAR, why=f"10 standard deviations within the wire's ±{MAX_ABS:g}")


class FormationTable(Table, frozen=True, kw_only=True):
    """``[world.formation]``: p_i(t) = R(t)^T p_i(0), R(t) = Ra(rate·t, axis) (§3.3.4, §4.5); an
    axis and an expression, read by hand (zswarm.scenario.reading)."""

    axis: Any
    rate: Any


class WorldTable(Table, frozen=True, kw_only=True):
    """``[world]``: the truth's step and sensor rate, the plant, the sensors fitted."""

    step: Annotated[float, bounds(positive=True, maxv=0.001, minv=MIN_WORLD_STEP_S)] = 0.001  # s
    sensor_rate: Annotated[float, bounds(positive=True)] = 200.0  # Hz, <= 1/step (checked by the loader)
    formation: FormationTable | None = None
    plant: Plant | None = None  # None: the plant that reads what the algorithm sends
    sensors: Any = None  # a list of sensor names (zswarm.scenario.algorithm.SENSORS), checked in _plant
    commands: dict[str, Any] = msgspec.field(default_factory=dict)  # a CommandPolicy, read once the plant is known to take commands


class NoiseTable(Table, frozen=True, kw_only=True):
    """``[noise]``: variances as the papers state them (attitude: R_i exp([n_R]^x), §5.6;
    rel_pos: ⁱp_ij + n per axis, m², De Carli et al. (2))."""

    gyro_var: Annotated[float, _ADDED_NOISE] = 0.0
    bearing_var: Annotated[float, bounds(nonneg=True)] = 0.0
    velocity_var: Annotated[float, _ADDED_NOISE] = 0.0
    rel_att_var: Annotated[float, bounds(nonneg=True)] = 0.0
    attitude_var: Annotated[float, bounds(nonneg=True)] = 0.0
    rel_pos_var: Annotated[float, _ADDED_NOISE] = 0.0


def _plant(c: _Ctx, w: WorldTable, info: AlgorithmSpec, algo: str) -> tuple[str, CommandPolicy, frozenset[str] | None]:
    """``[world] plant``, ``[world.commands]`` and ``[world] sensors``, checked against what the
    algorithm sends (SPEC.command) and measures (SPEC.sensors)."""
    from zswarm.scenario.algorithm import SENSORS

    sends = {k: f.shape for k, f in info.command.items()}
    plant: str = w.plant or next((p for p in PLANTS if sends and dict(PLANT_INPUTS[p]) == sends), "prescribed")
    reads = dict(PLANT_INPUTS[plant])
    if sends and sends != reads:
        raise c.err("world.plant", f"{algo} sends {sends or 'nothing'} on cmd/<i>, but the {plant!r} plant reads {reads or 'nothing'}", plant)
    if plant != "prescribed" and w.formation is not None:
        raise c.err("world.formation", f"a formation is a prescribed motion; the {plant!r} plant moves by its own dynamics")
    cm = c.table(w.commands, "world.commands", set(CommandPolicy.__struct_fields__))
    if cm and plant == "prescribed":
        raise c.err("world.commands", "the prescribed plant takes no commands")
    policy = c.typed(cm, "world.commands", CommandPolicy)
    fitted = None
    if w.sensors is not None:
        raw = w.sensors
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
    Jt = tuple(J.ravel().tolist())
    problem = _inertia_problem(Jt)
    if problem is not None:
        raise c.err(fld, problem, v)
    return Jt


@functools.lru_cache(maxsize=256)
def _inertia_problem(Jt: tuple[float, ...]) -> str | None:
    """What is wrong with the inertia ``Jt`` (row-major), None if nothing; remembered, as a
    basin's draws read the same inertias once a draw."""
    J = np.array(Jt).reshape(3, 3)
    if not np.allclose(J, J.T, rtol=1e-9, atol=1e-12):
        return "must be symmetric"
    lam = np.linalg.eigvalsh(0.5 * (J + J.T))
    if lam[0] <= 0:
        return f"must be positive definite (eigenvalues {np.round(lam, 6).tolist()})"
    return None
