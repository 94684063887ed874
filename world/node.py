"""The world node: integrates the truth and publishes sensor packets and truth.

Engine-agnostic: ``zswarm sim`` calls :meth:`World.sample` at virtual times;
``python -m world`` calls it from a real-time loop.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from world import sensors
from world.motion import PrescribedMotion, prescribed
from world.plant import CommandInbox, KinematicPlant, RigidBodyPlant
from zswarm.scenario.programs import WorldProgram
from zswarm.scenario.world_config import PLANT_INPUTS
from zswarm.transport import keys
from zswarm.transport.bus import Bus


@functools.lru_cache(maxsize=1024)  # per command message: the parse once per key (the agents' few)
def _cmd_agent(key: str) -> int | None:
    """The agent id of a ``zswarm/<run>/cmd/<i>`` key (None: not one)."""
    k = keys.parse(key)
    return k.src if k is not None and k.kind == "cmd" else None


PLAN_SAMPLES = 200  # sensor samples whose motion is evaluated at once (1 s at 200 Hz)


class Sensing:
    """Every agent's sensor packet at a sample of the truth, with the scenario's noise: agent i's
    from its own generator seeded by ``(seed, i)`` and drawn in one order (gyro, bearings,
    relative attitudes, velocity, body velocity, attitude, relative positions), so a seed gives
    the same measurements on every engine (the world's processes, sim, the batched engine)."""

    def __init__(self, program: WorldProgram) -> None:
        bodies = program.bodies
        # What each agent's algorithm declares it measures (zswarm.scenario.algorithm.SENSORS).
        self.sensors = {b.id: b.sensors for b in bodies}
        want = frozenset().union(*self.sensors.values())
        self.want_bearings = "bearings" in want
        self.ids = list(program.ids)
        self.index = {i: k for k, i in enumerate(self.ids)}
        self.bias = np.array([b.gyro_bias for b in bodies])
        noise = program.noise
        self.gyro_std = math.sqrt(noise.gyro_var)
        self.bearing_std = math.sqrt(noise.bearing_var)
        self.velocity_std = math.sqrt(noise.velocity_var)
        self.rel_att_std = math.sqrt(noise.rel_att_var)
        self.attitude_std = math.sqrt(noise.attitude_var)
        self.rel_pos_std = math.sqrt(noise.rel_pos_var)
        seed = program.seed
        self.rngs = {i: np.random.default_rng([seed % (1 << 63), i]) for i in self.ids}
        self.nbrs = {b.id: b.bearing_to for b in bodies}
        self.sensed = {b.id: b.senses for b in bodies}
        # Bearing pairs (i, j), in each agent's neighbour order (the noise draw order).
        pairs = [(i, j) for i in self.ids for j in self.nbrs[i]]
        self.pair_i = np.array([self.index[i] for i, _ in pairs], dtype=int)
        self.pair_j = np.array([self.index[j] for _, j in pairs], dtype=int)
        self.pairs_of = {i: [(q, j) for q, (a, j) in enumerate(pairs) if a == i] for i in self.ids}

    def bearings(self, R: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Every pair's clean bearing at once, (pairs, 3) in ``pairs_of``'s numbering (None: no agent measures bearings)."""
        return sensors.bearings(R, p, self.pair_i, self.pair_j) if self.want_bearings else None

    def measure(self, R: NDArray[np.float64], p: NDArray[np.float64], W: NDArray[np.float64], V: NDArray[np.float64] | None) -> dict[int, dict[str, object]]:
        """Each agent's packet fields from the truth's attitudes R (n, 3, 3), positions p, body
        rates W and inertial velocities V (None: the agents do not move)."""
        B = self.bearings(R, p)
        if B is not None:
            B.flags.writeable = False  # this sample's own: its rows go out as they are (see _sealed)
        out: dict[int, dict[str, object]] = {}
        for i in self.ids:
            a = self.index[i]
            rng = self.rngs[i]
            want = self.sensors[i]
            m: dict[str, object] = {}
            if "gyro" in want:
                m["gyro"] = sensors.gyro(W[a], self.bias[a], self.gyro_std, rng)
            if B is not None and "bearings" in want:
                m["bearings"] = {j: sensors.noisy_bearing(B[q], self.bearing_std, rng) for q, j in self.pairs_of[i]}
            if "rel_att" in want:
                m["rel_att"] = {j: sensors.relative_attitude(R[a], R[self.index[j]], self.rel_att_std, rng) for j in self.nbrs[i]}
            if V is not None and "velocity" in want:
                m["velocity"] = sensors.velocity(V[a], self.velocity_std, rng)
            if "velocity_body" in want:
                m["velocity_body"] = sensors.velocity(R[a].T @ (V[a] if V is not None else np.zeros(3)), self.velocity_std, rng)
            # Own attitude: R_i exp([n_R]^x) (§5.6; exact for the thesis' leaders, who
            # know their pose).  Drawn last: earlier scenarios keep their measurements.
            if "attitude" in want:
                m["attitude"] = sensors.attitude(R[a], self.attitude_std, rng)
            if "position" in want:
                m["position"] = p[a]
            if "rel_pos" in want:
                # toward the robots i senses (Body.senses): the sensing graph is directed
                m["rel_pos"] = {j: sensors.relative_position(R[a], p[a], p[self.index[j]], self.rel_pos_std, rng) for j in self.sensed[i]}
            out[i] = _sealed(m)
        return out


def _sealed(m: dict[str, object]) -> dict[str, object]:
    """``m`` with the arrays this sample made read-only: a message holds its arrays read-only,
    and copies a sender's writable ones (zswarm.transport.message_checks); a fresh array no one
    else holds need not be copied, and the wire's C check takes it as it takes a decoded one
    (``zswarm sim``: a sense packet's checks then cost what a received one's do).  Only arrays
    that own their data, or rows of the bearings computed for this sample (read-only already):
    a view of the truth (a noise-free attitude, the position) stays writable and is copied."""
    for v in m.values():
        if type(v) is dict:
            for x in v.values():
                if type(x) is np.ndarray and x.base is None:
                    x.flags.writeable = False
        elif type(v) is np.ndarray and v.base is None:
            v.flags.writeable = False
    return m


class World:
    """Truth and sensors of a scenario, publishing on ``bus``.

    Sensor samples are taken at world times ``k / sensor_rate``; the noise of
    agent i comes from its own generator seeded by ``(seed, i)``, so a seed
    gives the same measurements on every engine.
    """

    def __init__(self, program: WorldProgram, bus: Bus, run: str, now: Callable[[], float] | None = None, inc: int = 0) -> None:
        """``program``: everything the world runs on (zswarm.scenario.programs.world_program)."""
        self.inc = inc  # this process's incarnation, in every message it sends (wire.py)
        self.program = program
        self.moving = program.moving
        self.run = run
        # World time, for the arrival of commands: virtual in sim; a run sets its clock
        # here once the epoch is announced (before that no agent sends a command).
        self.now: Callable[[], float] = now if now is not None else self.next_time
        self.commands: CommandInbox | None = None
        self.motion: PrescribedMotion | RigidBodyPlant | KinematicPlant
        bodies = program.bodies
        if program.plant in ("kinematic", "rigid_body"):
            self.commands = CommandInbox(list(program.ids), lambda: self.now(), program.command_link, program.seed, program.commands, PLANT_INPUTS[program.plant])
            R0, p0 = np.array([b.R_matrix for b in bodies]), np.array([b.p for b in bodies])
            if program.plant == "kinematic":
                self.motion = KinematicPlant(R0, p0, program.step, self.commands)
            else:
                J = np.array([np.array(b.J).reshape(3, 3) for b in bodies])
                self.motion = RigidBodyPlant(R0, p0, np.array([b.omega0 for b in bodies]), J, program.step, self.commands)
            bus.subscribe(keys.cmds_all(run), self.commands.handler(_cmd_agent))
        else:
            self.motion = prescribed(program)
        self.sensing = Sensing(program)
        self.ids = self.sensing.ids
        self.pub_sense = {i: bus.publisher(keys.sense(run, i)) for i in self.ids}
        self.pub_truth = bus.publisher(keys.truth(run))
        self.pub_stats = bus.publisher(keys.stats(run, "world", 0))
        self.pub_final = bus.publisher(keys.stats(run, "world", 0), block=True)  # see AgentNode.pub_final
        self.stats_seq = 0
        self.k = 0  # index of the next sensor sample
        self.seq = 0
        self.samples = 0
        self.late = 0  # samples the real-time loop had to skip
        # Samples taken more than one sensor period after their due time, and the most late one
        # (s): the real-time loop's own lateness, which an agent's tick without a new packet
        # comes from on a machine short of CPU (results.overload: the late sensor data named).
        self.taken_late = 0
        self.max_lateness = 0.0

    @property
    def period(self) -> float:
        return 1.0 / self.program.sensor_rate

    def next_time(self) -> float:
        return self.k * self.period

    def sample(self) -> float:
        """Advance the truth to the next sample time, publish it, return that time."""
        t = self.next_time()
        if isinstance(self.motion, PrescribedMotion) and t > self.motion.planned_through():
            # ω_i(t), v_i(t) for the next samples at once (PrescribedMotion.plan): k·period as
            # next_time computes it, element by element.
            self.motion.plan(np.arange(self.k, self.k + PLAN_SAMPLES) * self.period)
        self.motion.advance_to(t)
        R, p = self.motion.R, self.motion.p
        W = self.motion.omega_now()
        V = self.motion.velocity() if self.moving else None
        seq = self.seq
        if isinstance(self.motion, RigidBodyPlant):
            self.pub_truth.publish("truth", 0, seq, t, inc=self.inc, ids=self.ids, R=R, p=p, w=W, tau=self.motion.tau)
        elif isinstance(self.motion, KinematicPlant):
            self.pub_truth.publish("truth", 0, seq, t, inc=self.inc, ids=self.ids, R=R, p=p, w=W, u=self.motion.u)
        else:
            self.pub_truth.publish("truth", 0, seq, t, inc=self.inc, ids=self.ids, R=R, p=p, w=W)
        for i, m in self.sensing.measure(R, p, W, V).items():
            self.pub_sense[i].publish("sense", 0, seq, t, inc=self.inc, **m)
        self.seq += 1
        self.samples += 1
        self.k += 1
        return t

    def lateness(self, late_s: float) -> None:
        """Count the next sample as taken ``late_s`` wall seconds (in world time) after it was due."""
        if late_s > self.period:
            self.taken_late += 1
        self.max_lateness = max(self.max_lateness, late_s)

    def skip_to(self, t: float) -> int:
        """Skip sample indices whose time is before ``t`` (the loop fell behind); return how many."""
        k_new = max(self.k, int(math.floor(t / self.period + 1e-9)))
        skipped = k_new - self.k
        self.k = k_new
        self.late += skipped
        return skipped

    def counters(self) -> dict[str, object]:
        c: dict[str, object] = {
            "samples": self.samples,
            "late": self.late,
            "taken_late": self.taken_late,
            "max_lateness_s": round(self.max_lateness, 6),
            "sent": {f"world->{i}": self.seq for i in self.ids},
        }
        if self.commands is not None:
            c.update(self.commands.counters())
        return c

    def publish_stats(self, t: float, final: bool = False) -> None:
        counters = self.counters()
        counters["final"] = final
        (self.pub_final if final else self.pub_stats).publish("stats", 0, self.stats_seq, t, inc=self.inc, role="world", counters=counters)
        self.stats_seq += 1
