"""``zswarm compose``: a docker-compose file for any scenario.

One container per process, as ``zswarm run`` starts them: a Zenoh router,
the recorder, the world and one service per agent, all from one image.  The
scenario's folder is mounted read-only at ``/scenario`` (so a user's own
algorithm module beside it is found as on the host), the results folder of
the host (``${ZSWARM_RESULTS:-./runs}``) at ``/results``.

Networks are user-defined bridges, ``internal`` (no route out of them, so a
run's traffic stays between its containers):

* ``flat``: one network ``zswarm`` for everything;
* ``routed``: the router, world and recorder on ``core``; the agents on
  ``agents`` with a second router ``router-agents`` on both networks.  Every
  agent sample crosses two routers, as with agents on another site.

The router exits once the recorder has come and gone (``--exit-after-run``),
the world at the end of the scenario, each agent at the world's stop, so
``docker compose up`` returns by itself when the results are written.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from zswarm.scenario import Scenario
from zswarm.transport import keys, procutil
from zswarm.transport.keys import SECRET_ENV

PORT = 7447


def services(
    sc: Scenario,
    scenario_file: str,
    scenario_dir: str,
    image: str,
    build: dict[str, Any] | None,
    run_id: str,
    results: str,
    network: str = "flat",
    duration: float | None = None,
    time_scale: float = 1.0,
    seed: int | None = None,
    live: tuple[str, int] | None = None,
) -> dict[str, Any]:
    """The compose document (a dict; :func:`to_yaml` writes it)."""
    if network not in ("flat", "routed"):
        raise ValueError(f"network: 'flat' or 'routed' (got {network!r})")
    topo = f"/scenario/{scenario_file}"
    common = ["--run-id", run_id, *(["--seed", str(seed)] if seed is not None else [])]
    core = "zswarm" if network == "flat" else "core"
    edge_net = "zswarm" if network == "flat" else "agents"
    agent_router = "router" if network == "flat" else "router-agents"

    def svc(command: list[str], nets: list[str], **extra: Any) -> dict[str, Any]:
        s: dict[str, Any] = {"image": image}
        if build is not None:
            s["build"] = build  # every service names the same image; compose builds it once
        s["command"] = command
        # The run's secret (keys.SECRET_ENV) from the host's environment or .env: with one,
        # only these services can start or stop the run or stand for its processes.
        s["environment"] = {SECRET_ENV: "${" + SECRET_ENV + ":-}"}
        s["networks"] = nets
        s["init"] = True  # a real PID 1: signals reach zswarm, zombies are reaped
        s.update(extra)
        return s

    out: dict[str, Any] = {}
    out["router"] = svc(["zswarm", "router", "--listen", f"tcp/0.0.0.0:{PORT}", "--exit-after-run", run_id], [core])
    if network == "routed":
        out["router-agents"] = svc(
            ["zswarm", "router", "--listen", f"tcp/0.0.0.0:{PORT}", "--connect", f"tcp/router:{PORT}", "--exit-after-run", run_id],
            [core, edge_net],
            depends_on=["router"],
        )
    vol_scenario = f"{scenario_dir}:/scenario:ro"
    rec_cmd = ["zswarm", "record", topo, "--out", f"/results/{sc.name}", "--connect", f"tcp/router:{PORT}", *common]
    rec_extra: dict[str, Any] = {"volumes": [vol_scenario, f"{results}:/results"], "depends_on": ["router"]}
    rec_nets = [core]
    if live is not None:  # the recorder listens in its container; the host publishes HOST:PORT
        rec_cmd += ["--live", f"0.0.0.0:{live[1]}"]
        rec_nets.append("view")
        rec_extra["ports"] = [f"{live[0]}:{live[1]}:{live[1]}"]
    out["recorder"] = svc(rec_cmd, rec_nets, **rec_extra)
    world_cmd = ["python", "-m", "world", "--topology", topo, "--wait-for-recorder", "--connect", f"tcp/router:{PORT}", "--time-scale", f"{time_scale:g}", *common]
    if duration is not None:
        world_cmd += ["--duration", f"{duration:g}"]
    out["world"] = svc(world_cmd, [core], volumes=[vol_scenario], depends_on=["router"])
    for i in sc.ids:
        out[f"agent{i}"] = svc(
            ["python", "-m", "agent", "--topology", topo, "--id", str(i), "--connect", f"tcp/{agent_router}:{PORT}", *common],
            [edge_net],
            volumes=[vol_scenario],
            depends_on=[agent_router],
        )
    nets: dict[str, Any] = {core: {"internal": True}}
    if network == "routed":
        nets[edge_net] = {"internal": True}
    if live is not None:
        nets["view"] = {}  # the one network with a way out: the viewer's port on the host
    return {"services": out, "networks": nets}


def _scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return json.dumps(v)
    return json.dumps(str(v), ensure_ascii=False)  # a JSON string is a YAML double-quoted scalar


def to_yaml(doc: Any, indent: int = 0) -> str:
    """YAML for the compose document's shapes (maps, lists of scalars or maps, scalars)."""
    pad = "  " * indent
    lines: list[str] = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            key = k if k.replace("-", "").replace("_", "").isalnum() else json.dumps(k)
            if isinstance(v, dict) and v:
                lines.append(f"{pad}{key}:")
                lines.append(to_yaml(v, indent + 1))
            elif isinstance(v, dict):
                lines.append(f"{pad}{key}: {{}}")
            elif isinstance(v, list) and all(not isinstance(x, (dict, list)) for x in v):
                lines.append(f"{pad}{key}: [{', '.join(_scalar(x) for x in v)}]")
            elif isinstance(v, list):
                lines.append(f"{pad}{key}:")
                for x in v:
                    body = to_yaml(x, indent + 2).lstrip()
                    lines.append(f"{pad}  - {body}")
            else:
                lines.append(f"{pad}{key}: {_scalar(v)}")
        return "\n".join(lines)
    return pad + _scalar(doc)


def write(
    sc: Scenario,
    topology: Path,
    out: Path | None,
    image: str,
    build_context: Path | None,
    base: str | None,
    run_id: str,
    results: str,
    network: str,
    duration: float | None,
    time_scale: float,
    seed: int | None,
    live: tuple[str, int] | None,
    argv: Sequence[str] = (),
) -> str:
    """The compose file's text; paths in it are relative to ``out``'s folder (or the current one)."""
    where = (out.parent if out is not None else Path.cwd()).resolve()
    scen_dir = _rel(topology.resolve().parent, where)
    build: dict[str, Any] | None = None
    if build_context is not None:
        build = {"context": _rel(build_context.resolve(), where)}
        if base is not None:
            build["args"] = {"BASE": base}
    doc = services(sc, topology.name, scen_dir, image, build, run_id, results, network, duration, time_scale, seed, live)
    head = [
        f"# {sc.name}: {len(sc.ids)} agents, one container per process ({network} network).",
        f"# Made by: zswarm compose {' '.join(argv)}".rstrip(),
        "# docker compose up   (or docker-compose up): returns when the run's results are written to",
        f"# ${{ZSWARM_RESULTS:-./runs}}/{sc.name}/ (summary.json, recording.mcap, plots).",
    ]
    return "\n".join(head) + "\n" + to_yaml(doc) + "\n"


def _rel(p: Path, base: Path) -> str:
    r = os.path.relpath(p, base)
    return r if r.startswith(".") or os.path.isabs(r) else f"./{r}"


# --------------------------------------------------------------------------- the command (zswarm.cli dispatches here)


def command(args: argparse.Namespace) -> int:
    from zswarm.engines import compose

    if args.live is not None and args.live[1] == 0:
        procutil.fail_usage("compose --live HOST:PORT: a port for Docker to publish (0, a free port of a process, has no meaning there)")
    sc = procutil.load_args(args)
    undone = [f.describe() for f in sc.faults if f.kind != "cut"]
    if undone:
        # A cut is the receivers' link emulation and happens in containers too; a kill, stop
        # or router fault needs a launcher, which compose does not have.
        print(f"zswarm compose: note: docker compose does not carry out these faults (zswarm run and sim do): {'; '.join(undone)}", file=sys.stderr)
    topology = Path(args.topology)
    if args.overrides:
        if args.output is None:
            procutil.fail_usage("--set needs -o FILE (the scenario as run is written beside it)")
        topology = args.output.with_name(args.output.stem + ".scenario.toml")
        topology.write_text(sc.text, encoding="utf-8")
    build = None
    if not args.no_build:
        build = args.build_context
        if build is None:
            src = Path(__file__).resolve().parent.parent
            build = src if (src / "Dockerfile").exists() else None
        elif not (build / "Dockerfile").exists():
            procutil.fail_usage(f"{build}: no Dockerfile there")
    text = compose.write(
        sc,
        topology,
        args.output,
        args.image,
        build,
        args.base,
        keys.check_run_id(args.run_id),
        args.results,
        args.network,
        args.duration,
        args.time_scale,
        args.seed,
        args.live,
        argv=sys.argv[2:],
    )
    procutil.write_output(text, args.output, f"({len(sc.ids)} agents); run it with: docker compose -f {args.output} up")
    return 0
