"""What each process of a run is built from: an agent's :class:`AgentProgram` and the world's
:class:`WorldProgram`, composed from a scenario once (:func:`agent_program`,
:func:`world_program`) and handed whole to the process, which sees nothing else of the
scenario.

An agent gets its own entry (id, role, neighbours, clock), its algorithm module and that
module's typed ``Gains`` (its gains with the scenario's ``[algorithm.params]`` on the fields
of the same names, :func:`zswarm.scenario.algorithm.make_gains`), its initial state, the
models of the links it receives on, its stale policy and the seed its link and clock draws
come from.  The world gets every body's start and motion, the plant, the noise, what each
agent measures and toward whom, the command policy and the command links.  Composing both
is the only place a parameter walks from the scenario's tables to a process.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType, ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from zswarm.scenario.agent_config import StartPose
from zswarm.scenario.algorithm import AlgorithmSpec, Initial, StalePolicy, initial_value, make_gains
from zswarm.scenario.clock import ClockSpec
from zswarm.scenario.expr import Expr
from zswarm.scenario.links import LinkSpec
from zswarm.scenario.world_config import CommandPolicy, NoiseTable

if TYPE_CHECKING:
    from zswarm.scenario import Formation, Scenario


@dataclass(frozen=True, slots=True)
class AgentProgram:
    """Everything agent ``id``'s process runs on (agent/runtime.py's AgentNode)."""

    id: int
    role: str
    algorithm: ModuleType  # its module (zswarm.scenario.algorithm interface)
    gains: Any  # the module's Gains: this agent's gains and the scenario's params, typed
    initial: Initial  # what its state starts from (SPEC.initial, its tree edges, the others' stated values)
    clock: ClockSpec
    neighbors: tuple[int, ...]  # N_i: in-neighbours
    k_neighbors: tuple[float, ...]  # k_ij, same order
    out_neighbors: tuple[int, ...]
    senses: tuple[int, ...]  # the robots whose relative positions it measures
    moving: bool  # positions change (the world's motion is not fixed)
    stale: StalePolicy
    part_rate_scale: float  # every part's declared rate times this (zswarm.studies.step_size.refine)
    seed: int  # the run's seed: its clock's and its links' draws
    # The models of the links it receives on ("world->i", "j->i"); None: none is emulated.
    links: Mapping[str, LinkSpec] | None = None

    @property
    def spec(self) -> AlgorithmSpec:
        """Its algorithm's declaration (``SPEC``)."""
        s: AlgorithmSpec = self.algorithm.SPEC
        return s

    @property
    def tree_edges(self) -> Mapping[int, tuple[int, bool]]:
        """§4: tree neighbour j -> (edge index k, whether this agent heads k and owns ξ_k)."""
        return self.initial.tree_edges

    @property
    def clock_seed(self) -> int:
        """The seed of its clock's jitter (AgentClock): one stream per agent and run seed."""
        return (self.seed * 1000003 + self.id) % (1 << 63)


@dataclass(frozen=True, slots=True)
class Body(StartPose):
    """One agent's body as the world moves and measures it."""

    id: int
    R: tuple[float, ...]  # R_i(0), row-major 3×3
    p: tuple[float, float, float]  # p_i(0)
    omega: tuple[Expr, Expr, Expr]  # ω_i(t) (a rigid body: ω_i(0) from these at t = 0)
    gyro_bias: tuple[float, float, float]
    velocity: tuple[Expr, Expr, Expr] | None = None  # v_i(t) (None: fixed or a formation)
    J: tuple[float, ...] | None = None  # inertia, row-major 3×3 (rigid_body plant)
    sensors: frozenset[str] = frozenset()  # what the world measures for it (zswarm.scenario.algorithm.SENSORS)
    bearing_to: tuple[int, ...] = ()  # bearings and relative attitudes toward these (its in- and out-neighbours)
    senses: tuple[int, ...] = ()  # relative positions toward these


@dataclass(frozen=True, slots=True)
class WorldProgram:
    """Everything the world's process runs on (world/node.py's World and Sensing)."""

    bodies: tuple[Body, ...]
    plant: str  # "prescribed" | "rigid_body" | "kinematic"
    step: float  # s, the truth's integration step
    sensor_rate: float  # Hz
    noise: NoiseTable
    seed: int  # the run's seed: every agent's sensor noise, the command links' draws
    formation: Formation | None = None
    moving: bool = False
    commands: CommandPolicy = CommandPolicy()
    command_links: Mapping[str, LinkSpec] = field(default_factory=dict)  # "i->world" -> its model

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(b.id for b in self.bodies)

    def command_link(self, name: str) -> LinkSpec:
        """The model of command link ``name`` ("3->world")."""
        return self.command_links.get(name, LinkSpec())


def agent_program(sc: Scenario, agent_id: int, seed: int) -> AgentProgram:
    """Agent ``agent_id``'s program in ``sc`` for a run of ``seed`` (KeyError: no such agent)."""
    a = sc.agent(agent_id)
    algo = sc.module_for(a.role)
    aspec: AlgorithmSpec = algo.SPEC
    values: dict[str, Any] = dict(a.gains)
    if sc.params is not None:  # [algorithm.params]: onto the Gains fields of the same names
        values.update(sc.params.gains(sc.ids))
    tree_edges: dict[int, tuple[int, bool]] = {}
    for k, (h, t) in enumerate(sc.oriented, start=1):
        if agent_id in (h, t):
            tree_edges[t if h == agent_id else h] = (k, h == agent_id)
    est = a.estimate
    initial = Initial(
        agent_id,
        MappingProxyType({name: initial_value(f, est.get(name, f.default)) for name, f in aspec.initial.items()}),
        est.stated,
        MappingProxyType(tree_edges),
        {b.id: {n: b.estimate[n] for n in b.estimate.stated} for b in sc.agents},
        seed,
        np.array(a.p),
    )
    names = [f"world->{agent_id}"] + [f"{j}->{agent_id}" for j in a.neighbors]
    return AgentProgram(
        id=agent_id,
        role=a.role,
        algorithm=algo,
        gains=make_gains(algo, values),
        initial=initial,
        clock=a.clock,
        neighbors=a.neighbors,
        k_neighbors=a.k_neighbors,
        out_neighbors=sc.out_neighbors(agent_id),
        senses=sc.sensed(agent_id),
        moving=sc.moving,
        stale=sc.stale,
        part_rate_scale=sc.part_rate_scale,
        seed=seed,
        links=MappingProxyType({n: sc.link_spec(n) for n in names}) if sc.links_active else None,
    )


def world_program(sc: Scenario, seed: int) -> WorldProgram:
    """The world's program in ``sc`` for a run of ``seed``."""
    bodies = tuple(
        Body(a.id, a.R, a.p, a.omega, a.gyro_bias, a.velocity, a.J, sc.sensors_of(a.id), sc.graph_neighbors(a.id), sc.sensed(a.id)) for a in sc.agents
    )
    noise = NoiseTable(
        gyro_var=sc.gyro_var,
        bearing_var=sc.bearing_var,
        velocity_var=sc.velocity_var,
        rel_att_var=sc.rel_att_var,
        attitude_var=sc.attitude_var,
        rel_pos_var=sc.rel_pos_var,
    )
    return WorldProgram(
        bodies=bodies,
        plant=sc.plant,
        step=sc.step,
        sensor_rate=sc.sensor_rate,
        noise=noise,
        seed=seed,
        formation=sc.formation,
        moving=sc.moving,
        commands=sc.commands,
        command_links=MappingProxyType({f"{i}->world": sc.link_spec(f"{i}->world") for i in sc.ids}),
    )
