"""A Foxglove layout for a recording (``foxglove-layout.json`` in every results folder), built with
the Foxglove SDK's own layout types (``foxglove.layouts``): a 3-D panel on the ``world`` frame
whose camera takes in every body, and plots of what the recording holds — each agent's attitude
and position errors, the §4 and De Carli edge errors, the Chapter 5 edges' relative attitudes,
the links' losses — one series per agent, edge or link, labelled.  In Foxglove or Lichtblick:
*Layouts* → *Import from file*, then open the recording."""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

_AGENT = re.compile(r"^/errors/(\d+)$")
_EDGE = re.compile(r"^/errors/edge/(\d+)_(\d+)$")
_SYNC = re.compile(r"^/sync/edge/(\d+)_(\d+)$")
_LINK = re.compile(r"^/links/(\d+)_to_(\d+)$")
MAX_LINK_SERIES = 40  # past this many links the losses plot would be a blur: left out


def _num(m: re.Match[str]) -> tuple[int, ...]:
    return tuple(int(g) for g in m.groups())


def foxglove_layout(channels: Iterable[str], extent: float, title: str = "") -> str:
    """The layout's JSON for a recording with these ``channels`` (topics, ``/errors/3``, ...) whose
    bodies lie within ``extent`` metres of the origin."""
    import foxglove.layouts as fl

    chans = set(channels)

    def matches(pattern: re.Pattern[str]) -> list[tuple[int, ...]]:
        return sorted(_num(m) for c in chans if (m := pattern.match(c)))

    def plot(name: str, series: list[tuple[str, str]], log: bool = False) -> fl.PlotPanel:
        return fl.PlotPanel(
            title=name,
            config=fl.PlotConfig(
                paths=[fl.PlotSeries(value=path, label=label) for path, label in series],
                show_legend=True,
                legend_display="left",
                y_axis_label=name,
                **({"min_y_value": 0} if not log else {}),
            ),
        )

    agents = matches(_AGENT)
    plots = []
    if agents:
        plots.append(plot("attitude error |R̃_i|_I", [(f"/errors/{i}.attitude", f"agent {i}") for (i,) in agents]))
        plots.append(plot("position error (m)", [(f"/errors/{i}.position", f"agent {i}") for (i,) in agents]))
    edges = matches(_EDGE)
    if edges:
        plots.append(plot("edge attitude |R̄_k|_I", [(f"/errors/edge/{h}_{t}.attitude", f"{h}-{t}") for h, t in edges]))
    sync = matches(_SYNC)
    if sync:
        plots.append(plot("relative attitude |R̄_k|_I (truth)", [(f"/sync/edge/{h}_{t}.attitude", f"{h}-{t}") for h, t in sync]))
    links = matches(_LINK)
    if links and len(links) <= MAX_LINK_SERIES:
        plots.append(plot("messages dropped per link", [(f"/links/{j}_to_{i}.dropped", f"{j}->{i}") for j, i in links]))
    three_d = fl.ThreeDeePanel(
        title=f"{title}: bodies (true and estimated frames)" if title else "bodies (true and estimated frames)",
        config=fl.ThreeDeeConfig(
            follow_tf="world",
            # Far enough back to take in every body (a 60° field of view: ~2.5 extents away).
            camera_state=fl.ThreeDeeCameraState(distance=max(5.0, 2.5 * extent), perspective=True, phi=55.0, theta_offset=45.0, target=(0.0, 0.0, 0.0)),
        ),
    )
    right = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=p) for p in plots]) if plots else None
    content = three_d if right is None else fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=3, content=three_d), fl.SplitItem(proportion=2, content=right)])
    return fl.Layout(content=content).to_json()


def write_layout(recording: Path, out: Path, extent: float, title: str = "") -> Path | None:
    """``out`` (foxglove-layout.json) for the recording's channels (read from its summary, or the
    whole file when it has none); None when there is no recording to lay out."""
    from mcap.reader import make_reader

    if not recording.exists():
        return None
    try:
        with open(recording, "rb") as f:
            summary = make_reader(f).get_summary()
            topics = [c.topic for c in summary.channels.values()] if summary is not None else []
    except Exception:  # noqa: BLE001 - a recording cut short has no summary: no layout, the rest of the report goes on
        return None
    out.write_text(foxglove_layout(topics, extent, title) + "\n")
    return out
