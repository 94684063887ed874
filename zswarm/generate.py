"""``zswarm generate``: N-agent scenarios for each algorithm family, valid by construction.

A family fixes the algorithm, its gains and parameters and the world's kind
(prescribed motion, a rotating formation, rigid bodies, vehicles), exactly as
the shipped scenario of the paper it comes from does (``topologies/``).  The
generator draws the rest from a seed: the graph (of the shape the family's
assumptions require), positions, motions and initial estimation errors.  The
text it writes is loaded by :func:`zswarm.scenario.loads` before it is
returned, so a bad draw can never reach a user (the draw is retried with the
next sub-seed; in practice the first one loads: random positions are generic).
"""

from __future__ import annotations

import argparse
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from zswarm import procutil
from zswarm.graph import SHAPES
from zswarm.scenario import Scenario, ScenarioError, loads

HYBRID_PARAMS_4 = {"A": [5, 8.57, 12], "u": [0, 0.6455, 0.7638], "gamma": 1.9251, "delta": 0.0030, "Xi": ["0.08*pi"]}
HYBRID_PARAMS_5 = {"A": [5, 8.57, 12], "u": [0, 0.6455, 0.7638], "gamma": 1.9251, "delta": 0.3848, "Xi": ["0.9*pi"]}
WORLD = {"step": 0.001, "sensor_rate": 200.0}


@dataclass(frozen=True)
class Family:
    """What a generated scenario of one family shares with the paper's scenario."""

    source: str  # the shipped scenario (topologies/) its algorithm section comes from
    what: str
    graph: str  # "leader_follower", "tree" or "sensing" (the loader's checks)
    algorithm: Mapping[str, Any]
    world: Mapping[str, Any]
    rate: float = 100.0  # agents' clock, Hz
    duration: float = 40.0
    estimate: tuple[str, ...] = ()  # what each agent's initial estimate sets (besides xi)


FAMILIES: dict[str, Family] = {
    "bearing-fixed": Family(
        "thesis-3.2-fixed8",
        "§3.2: bearing-based pose observer (3.3) + (3.14), agents at fixed positions",
        "leader_follower",
        {"name": "bearing_pose_fixed", "gains": {"k_R": 1.0, "k_p": 1.0}},
        WORLD,
        estimate=("p", "R"),
    ),
    "bearing-fixed-filtered": Family(
        "thesis-3.2-fixed8-filtered",
        "§3.2: filtered observer (3.8)-(3.9) + (3.14), agents at fixed positions",
        "leader_follower",
        {"name": "bearing_pose_fixed_filtered", "gains": {"k_Omega": 1.0, "k_p": 1.0}},
        WORLD,
        estimate=("p", "R"),
    ),
    "bearing-moving": Family(
        "thesis-3.3-moving5",
        "§3.3: observer (3.23) + (3.25) on a rotating formation",
        "leader_follower",
        {"name": "bearing_pose_moving", "gains": {"k_R": 3.0, "k_p": 1.0}},
        WORLD | {"formation": {"axis": [1, 0, 0], "rate": "pi/6"}},
        duration=30.0,
        estimate=("p", "R"),
    ),
    "relative-attitude": Family(
        "thesis-4.5-continuous5",
        "§4: continuous relative-attitude observer (4.3) + (4.8) on a tree, rotating formation",
        "tree",
        {"name": "relative_attitude_continuous", "gains": {"k_R": 1.1}, "params": {"A": [5, 8.57, 12]}},
        WORLD | {"formation": {"axis": [0, 0, 1], "rate": "pi/6"}},
        duration=30.0,
        estimate=("R",),
    ),
    "relative-attitude-hybrid": Family(
        "thesis-4.5-hybrid5",
        "§4: hybrid relative-attitude observer (4.25)-(4.26) on a tree, rotating formation",
        "tree",
        {"name": "relative_attitude_hybrid", "gains": {"k_R": 1.1, "k_xi": 3.5}, "params": HYBRID_PARAMS_4},
        WORLD | {"formation": {"axis": [0, 0, 1], "rate": "pi/6"}},
        duration=30.0,
        estimate=("R", "xi"),
    ),
    "relative-pose-hybrid": Family(
        "thesis-4.5-hybrid-pose5",
        "§4: hybrid pose observer (4.25)-(4.26) + (4.30)-(4.31) on a tree, rotating formation",
        "tree",
        {"name": "relative_pose_hybrid", "gains": {"k_R": 1.1, "k_xi": 3.5, "k_p": 1.0}, "params": HYBRID_PARAMS_4},
        WORLD | {"formation": {"axis": [0, 0, 1], "rate": "pi/6"}},
        duration=60.0,
        estimate=("p", "R", "xi"),
    ),
    "attitude-sync": Family(
        "thesis-5.6-continuous7",
        "§5: continuous attitude synchronization (5.24) of rigid bodies on a tree",
        "tree",
        {"name": "attitude_sync_continuous", "gains": {"k_R": 0.4, "k_omega": 0.1}, "params": {"A": [5, 8.57, 12]}},
        WORLD | {"plant": "rigid_body"},
        duration=150.0,
    ),
    "attitude-sync-hybrid": Family(
        "thesis-5.6-hybrid7",
        "§5: hybrid attitude synchronization (5.19), (5.21), (5.7) of rigid bodies on a tree",
        "tree",
        {"name": "attitude_sync_hybrid", "gains": {"k_R": 0.4, "k_omega": 0.1, "k_xi": 20}, "params": HYBRID_PARAMS_5},
        WORLD | {"plant": "rigid_body"},
        duration=150.0,
        estimate=("xi",),
    ),
    "attitude-sync-velocity-free": Family(
        "thesis-5.6-velocity-free7",
        "§5: velocity-free attitude synchronization (5.20)-(5.23), (5.7), (5.12) of rigid bodies on a tree",
        "tree",
        {
            "name": "attitude_sync_velocity_free",
            "gains": {"k_R": 0.4, "k_xi": 20, "k_Q": 30, "k_Qt": 3, "k_zeta": 20},
            "params": HYBRID_PARAMS_5 | {"delta_Q": 0.3848, "Pi": ["0.9*pi"]},
        },
        WORLD | {"plant": "rigid_body"},
        duration=150.0,
        estimate=("xi", "Q", "zeta"),
    ),
    "formation": Family(
        "decarli-8-formation",
        "De Carli et al.: relative yaw (7)/(8), common-frame yaw (13) and position (21) observers, formation control (30)",
        "sensing",
        {"name": "common_frame_formation", "gains": {"k_pe": 20.0, "k_psi": 600.0, "k_z": 40.0, "k_p": 1.0, "k_c": 0.5, "nu_max": 1.0}},
        WORLD | {"plant": "kinematic"},
        rate=200.0,
        duration=40.0,
    ),
}
GRAPHS = {"leader_follower": ("dag",), "tree": ("random", "chain", "star"), "sensing": ("ring", "ring-chords")}


def _r(x: float) -> float:
    """Rounded for a readable file: 4 decimals (the scenario is the rounded values)."""
    return round(float(x), 4) + 0.0


def _axis_angle(rng: np.random.Generator, lo: float, hi: float) -> dict[str, Any]:
    """A rotation of angle uniform in [lo, hi]·π about a uniformly random axis."""
    v = rng.normal(size=3)
    v /= np.linalg.norm(v)
    return {"angle": f"{_r(rng.uniform(lo, hi))}*pi", "axis": [_r(x) for x in v]}


def _omega(rng: np.random.Generator) -> list[str]:
    """ω_i(t), body frame: each component a constant or a sinusoid, like the thesis' (rad/s)."""
    out = []
    for _ in range(3):
        a = _r(rng.uniform(-2, 2))
        kind = rng.integers(3)
        if kind == 0:
            out.append(f"{a}")
        else:
            out.append(f"{a}*{'cos' if kind == 1 else 'sin'}({int(rng.integers(1, 10))}*t)")
    return out


def _positions(rng: np.random.Generator, n: int, spacing: float) -> np.ndarray:
    """n points in a cube holding about ``spacing`` m of room each, no two closer than
    ``spacing / 2`` (bearings are defined and well conditioned)."""
    side = spacing * max(2.0, math.ceil(n ** (1 / 3)) + 1)
    pts: list[np.ndarray] = []
    while len(pts) < n:
        q = rng.uniform(-side / 2, side / 2, size=3)
        if all(np.linalg.norm(q - x) >= spacing / 2 for x in pts):
            pts.append(q)
    return np.array(pts)


def _tree_edges(rng: np.random.Generator, n: int, shape: str) -> list[list[int]]:
    """[head, tail] pairs of a spanning tree on 1..n, each tail's head a lower id."""
    if shape == "chain":
        return [[i - 1, i] for i in range(2, n + 1)]
    if shape == "star":
        return [[1, i] for i in range(2, n + 1)]
    return [[int(rng.integers(1, i)), i] for i in range(2, n + 1)]


def _agents(fam: Family, rng: np.random.Generator, n: int, graph: str, in_degree: int, max_angle: float, spread: float) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The ``[[agents]]`` tables, and any top-level section the graph needs (``graph``, params)."""
    rigid = fam.world.get("plant") == "rigid_body"
    kinematic = fam.world.get("plant") == "kinematic"
    P = _positions(rng, n, 2.0 if not kinematic else 3.0)
    extra: dict[str, Any] = {}
    agents: list[dict[str, Any]] = [{"id": i} for i in range(1, n + 1)]
    edges: list[list[int]] = []
    if SHAPES[fam.graph].oriented:
        edges = _tree_edges(rng, n, graph)
        extra["graph"] = {"edges": edges}
    for k, a in enumerate(agents):
        i = k + 1
        if not rigid:
            a["p"] = [_r(x) for x in P[k]]
        if SHAPES[fam.graph].roles:
            a["role"] = "leader" if i <= 2 else "follower"
            if i > 2:
                a["neighbors"] = sorted(int(j) for j in rng.choice(np.arange(1, i), size=min(in_degree, i - 1), replace=False))
        if rigid:
            a["R"] = _axis_angle(rng, 0.0, 1.0)
            a["omega"] = [0, 0, 0]
            a["J"] = [1, 1, 1]
        elif kinematic:
            a["R"] = {"angle": f"{_r(rng.uniform(-math.pi, math.pi))}", "axis": [0, 0, 1]}
        else:
            a["omega"] = _omega(rng)
        est: dict[str, Any] = {}
        follower = fam.graph != "leader_follower" or i > 2
        if "p" in fam.estimate and follower:
            est["p"] = [_r(x) for x in P[k] + rng.normal(scale=spread / math.sqrt(3), size=3)]
        if "R" in fam.estimate and follower:
            est["R"] = _axis_angle(rng, 0.1 if fam.graph == "leader_follower" else 0.0, max_angle)
        if "xi" in fam.estimate:
            heads = [m + 1 for m, (h, _) in enumerate(edges) if h == i]
            if heads:
                est["xi"] = {str(m): 0.0 for m in heads}
        if "Q" in fam.estimate:
            est["Q"] = _axis_angle(rng, 0.0, 1.0)
        if "zeta" in fam.estimate:
            est["zeta"] = 0.0
        if est:
            a["estimate"] = est
    if fam.graph == "sensing":
        for k, a in enumerate(agents):
            i = k + 1
            nb = {i % n + 1}
            if graph == "ring-chords" and n > 3 and rng.random() < 0.5:
                nb.add(int(rng.choice([j for j in range(1, n + 1) if j not in (i, i % n + 1)])))
            a["neighbors"] = sorted(nb)
        # The formation (30): offsets on a circle, heights alternating, as in §IV's figure.
        r = 4.0 * max(1.0, n / 8)
        extra["p_star"] = [[_r(r * math.cos(2 * math.pi * k / n)), _r(r * math.sin(2 * math.pi * k / n)), float(k % 2)] for k in range(n)]
    return agents, extra


_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def _value(v: Any) -> str:
    """A TOML value on one line (inline arrays and tables: one agent reads as one block)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON's escapes are TOML's
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    raise TypeError(type(v))  # pragma: no cover - the generator writes only the kinds above


def dumps(doc: Mapping[str, Any]) -> str:
    """TOML of a scenario: one ``[section]`` per table (nested ones as ``[a.b]``), ``[[agents]]``
    last; leaves written inline."""
    out: list[str] = []

    def table(name: str, d: Mapping[str, Any]) -> None:
        leaves = {k: v for k, v in d.items() if not isinstance(v, dict) or k in ("formation",)}
        out.append(f"[{name}]")
        out.extend(f"{_key(k)} = {_value(v)}" for k, v in leaves.items())
        out.append("")
        for k, v in d.items():
            if k not in leaves:
                table(f"{name}.{_key(k)}", v)

    for name, d in doc.items():
        if name != "agents":
            table(name, d)
    for a in doc.get("agents", ()):
        out.append("[[agents]]")
        out.extend(f"{_key(k)} = {_value(v)}" for k, v in a.items())
        out.append("")
    return "\n".join(out)


def generate(
    family: str,
    n: int,
    seed: int = 1,
    *,
    graph: str | None = None,
    in_degree: int = 3,
    max_angle: float = 0.9,
    spread: float = 3.0,
    duration: float | None = None,
    name: str | None = None,
) -> tuple[str, Scenario]:
    """A scenario of ``family`` with ``n`` agents drawn from ``seed``: its TOML text, loaded.

    Parameters
    ----------
    graph
        The graph's shape: ``dag`` (leader–follower: followers pick ``in_degree``
        lower-numbered in-neighbours), ``random``/``chain``/``star`` (trees, head
        the lower id), ``ring``/``ring-chords`` (De Carli's sensing graph).
    max_angle
        Initial attitude estimation errors are drawn with angles up to this many π.
    spread
        RMS norm of the initial position estimation errors, m.

    Raises
    ------
    ValueError
        For an unknown family or graph, or parameters out of range.
    """
    fam = FAMILIES.get(family)
    if fam is None:
        raise ValueError(f"unknown family {family!r} (one of {', '.join(FAMILIES)})")
    graph = graph or GRAPHS[fam.graph][0]
    if graph not in GRAPHS[fam.graph]:
        raise ValueError(f"graph {graph!r} does not fit family {family} (one of {', '.join(GRAPHS[fam.graph])})")
    low = 3 if fam.graph == "leader_follower" else 2
    if not low <= n <= 1000:
        raise ValueError(f"n must be in {low}..1000 for family {family} (got {n})")
    if fam.graph == "leader_follower" and in_degree < 2:
        raise ValueError(f"in_degree must be >= 2 (each follower needs two non-collinear in-neighbours; got {in_degree})")
    if not 0.0 < max_angle <= 1.0:
        raise ValueError(f"max_angle must be in (0, 1] (a fraction of π; got {max_angle})")
    if spread < 0:
        raise ValueError(f"spread must be >= 0 (got {spread})")
    name = name or f"gen-{family}-{n}-s{seed}"
    last: ScenarioError | None = None
    for attempt in range(20):
        rng = np.random.default_rng([seed, n, attempt])
        agents, extra = _agents(fam, rng, n, graph, in_degree, max_angle, spread)
        algorithm = dict(fam.algorithm)
        if "p_star" in extra:
            algorithm["params"] = {"p_star": extra.pop("p_star")}
        doc: dict[str, Any] = {
            "scenario": {
                "name": name,
                "description": f"Generated: {fam.what}; {n} agents, graph {graph}, seed {seed} (zswarm generate)",
                "duration": float(duration if duration is not None else fam.duration),
                "seed": seed,
            },
            "algorithm": algorithm,
            "world": dict(fam.world),
            "clock": {"rate": fam.rate},
            **extra,
            "agents": agents,
        }
        head = f"# {doc['scenario']['description']}\n# Family {family}: the algorithm section is that of topologies/{fam.source}.toml.\n\n"
        text = head + dumps(doc)
        try:
            return text, loads(text, f"<{name}>")
        except ScenarioError as exc:  # e.g. collinear in-neighbours: draw again
            last = exc
    raise ValueError(f"no valid draw in 20 attempts: {last}")


def describe() -> list[tuple[str, str, tuple[str, ...]]]:
    """``(family, what, graph shapes)`` of every family, for ``zswarm generate --list``."""
    return [(k, f.what, GRAPHS[f.graph]) for k, f in FAMILIES.items()]


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    from zswarm import generate

    if args.list:
        for fam, what, graphs in generate.describe():
            print(f"{fam:<28} graphs: {', '.join(graphs):<22} {what}")
        return 0
    if args.family is None or args.agents is None:
        procutil.fail_usage("generate needs a FAMILY and -n N (zswarm generate --list shows the families)")
    try:
        text, sc = generate.generate(
            args.family,
            args.agents,
            args.seed,
            graph=args.graph,
            in_degree=args.in_degree,
            max_angle=args.max_angle,
            spread=args.spread,
            duration=args.duration,
            name=args.name,
        )
    except ValueError as exc:
        procutil.fail_usage(f"generate: {exc}")
    procutil.write_output(text, args.output, f": {sc.name}, {len(sc.ids)} agents, {sc.duration:g} s")
    return 0
