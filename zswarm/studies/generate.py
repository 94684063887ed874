"""``zswarm generate``: N-agent scenarios of each family's recipes, valid by construction.

A recipe (:class:`zswarm.families.contract.Recipe`, declared by its experiment family) fixes the
algorithm, its gains and parameters and the world's kind (prescribed motion, rigid
bodies, vehicles), exactly as the shipped scenario of the paper it comes from does
(``topologies/``).  The generator draws the rest from a seed: the graph (of the shape the
algorithm's assumptions require), positions, motions and initial estimation errors.  The
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
from typing import Any

import numpy as np

from zswarm.families import contract as zswarm_family
from zswarm.families.contract import Recipe
from zswarm.scenario import Scenario, ScenarioError, loads
from zswarm.scenario.graph import SHAPES
from zswarm.transport import procutil

# The graphs a generator draws for each kind of graph an algorithm asks for (zswarm.scenario.graph.SHAPES):
# with roles, a DAG of followers on lower-numbered in-neighbours; an oriented tree (head the
# lower id) of one of three shapes; otherwise a directed ring of sensing neighbours, with chords.
ROLES_GRAPHS = ("dag",)
TREE_GRAPHS = ("random", "chain", "star")
RING_GRAPHS = ("ring", "ring-chords")


def graphs_of(shape: str) -> tuple[str, ...]:
    """The graphs :func:`generate` draws for an algorithm's graph shape ``shape``."""
    s = SHAPES[shape]
    return ROLES_GRAPHS if s.roles else TREE_GRAPHS if s.oriented else RING_GRAPHS


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


def _agents(fam: Recipe, rng: np.random.Generator, n: int, graph: str, in_degree: int, max_angle: float, spread: float) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The ``[[agents]]`` tables, and any top-level section the graph needs (``graph``, params)."""
    roles = SHAPES[fam.graph].roles
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
        if roles:
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
        follower = not roles or i > 2
        if "p" in fam.estimate and follower:
            est["p"] = [_r(x) for x in P[k] + rng.normal(scale=spread / math.sqrt(3), size=3)]
        if "R" in fam.estimate and follower:
            est["R"] = _axis_angle(rng, 0.1 if roles else 0.0, max_angle)
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
    if graph in RING_GRAPHS:
        for k, a in enumerate(agents):
            i = k + 1
            nb = {i % n + 1}
            if graph == "ring-chords" and n > 3 and rng.random() < 0.5:
                nb.add(int(rng.choice([j for j in range(1, n + 1) if j not in (i, i % n + 1)])))
            a["neighbors"] = sorted(nb)
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
        # the world's own tables (its prescribed motion) on one line each
        leaves = {k: v for k, v in d.items() if not isinstance(v, dict) or (name == "world" and not any(isinstance(x, dict) for x in v.values()))}
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
    found = zswarm_family.recipes().get(family)
    if found is None:
        raise ValueError(f"unknown family {family!r} (one of {', '.join(zswarm_family.recipes())})")
    fam = found[1]
    kinds = graphs_of(fam.graph)
    graph = graph or kinds[0]
    if graph not in kinds:
        raise ValueError(f"graph {graph!r} does not fit family {family} (one of {', '.join(kinds)})")
    roles = SHAPES[fam.graph].roles
    low = 3 if roles else 2
    if not low <= n <= 1000:
        raise ValueError(f"n must be in {low}..1000 for family {family} (got {n})")
    if roles and in_degree < 2:
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
        if fam.params is not None:
            algorithm["params"] = fam.params(n)
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
    return [(k, r.what, graphs_of(r.graph)) for k, (_, r) in zswarm_family.recipes().items()]


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    from zswarm.studies import generate

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
