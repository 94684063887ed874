"""The scenario reference, generated from the typed schema at every build (so it cannot drift):
docs/reference/scenario-tables.md, included by docs/reference/scenario.md, holds for every table the loader reads with a
type (zswarm.scenario.ScenarioFile and the tables of each subsystem), its keys with their type,
default, bounds (the schema's :class:`zswarm.scenario.schema.Bounds`, worded as the loader
words its errors) and the unit or meaning written beside the field in the code; then each
shipped algorithm's gains (its SPEC) and the lists the loader checks values against."""

from __future__ import annotations

import ast
import inspect
import textwrap
import typing
from typing import Any

import msgspec


# The typed tables, in file order: (TOML table, type, what reads it by hand beside the type).
def _tables() -> list[tuple[str, type, str]]:
    from zswarm.scenario import AlgorithmTable, Header
    from zswarm.scenario.algorithm import StalePolicy
    from zswarm.scenario.clock import ClockSpec
    from zswarm.scenario.links import LinksTable, LinkTable
    from zswarm.scenario.world_config import CommandPolicy, NoiseTable, WorldTable

    return [
        ("[scenario]", Header, ""),
        ("[algorithm]", AlgorithmTable, "`gains` are the algorithm's own (below); `params` are read by its `SPEC.params`."),
        ("[algorithm.stale]", StalePolicy, "The algorithm's SPEC gives the defaults; this table overrides them."),
        ("[world]", WorldTable, "`formation` is `[world.formation]`: `axis` (a 3-vector) and `rate` (an expression of t, rad/s)."),
        ("[world.commands]", CommandPolicy, "Read when the plant takes commands (a rigid-body or kinematic plant)."),
        ("[noise]", NoiseTable, ""),
        ("[clock] and [agents.clock]", ClockSpec, "An agent's `[agents.clock]` starts from the scenario's `[clock]`."),
        ("[links]", LinksTable, "Agent-to-agent edges; `[links.per_link.\"j->i\"]` (also `\"world->i\"`, `\"i->world\"`) takes the same keys for one link."),
        ("[links.sensors] and [links.commands]", LinkTable, "World-to-agent sensor links and agent-to-world command links: zero unless set."),
    ]


def _comments(cls: type) -> dict[str, str]:
    """The comment written after each field of ``cls`` (its unit or meaning), by field name."""
    try:
        src = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    lines = src.splitlines()
    out = {}
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            line = lines[node.lineno - 1]
            if "#" in line:
                out[node.target.id] = line.split("#", 1)[1].strip()
    return out


def _type(t: Any) -> tuple[str, Any]:
    """A readable type and the schema's Bounds of an annotation."""
    from zswarm.scenario.schema import _unwrap

    base, b = _unwrap(t)
    if typing.get_origin(base) is typing.Literal:
        return " or ".join(f'`"{a}"`' for a in typing.get_args(base)), b
    if isinstance(base, type) and issubclass(base, msgspec.Struct):
        return "table", b
    name = getattr(base, "__name__", None) or str(base).replace("typing.", "")
    return {"float": "number", "int": "integer", "str": "string", "bool": "boolean", "dict": "table", "Any": "(read by hand)"}.get(name, name), b


def _bound_text(b: Any) -> str:
    if b is None:
        return ""
    if b.problem_text:
        return b.problem_text.removeprefix("must be ")
    parts = []
    if b.positive:
        parts.append("> 0")
    if b.nonneg:
        parts.append(">= 0")
    if b.minv is not None:
        parts.append(f">= {b.minv:g}")
    if b.maxv is not None:
        parts.append(f"<= {b.maxv:g}" + (f" ({b.why})" if b.why else ""))
    if b.within is not None:
        parts.append(f"within ±{b.within:g}{b.unit}" + (f" ({b.why})" if b.why and b.maxv is None else ""))
    return ", ".join(parts) or "finite"


def _default(cls: type, name: str) -> str:
    fields = cls.__struct_fields__
    defaults = cls.__struct_defaults__
    k = fields.index(name) - (len(fields) - len(defaults))
    if k < 0 or defaults[k] is msgspec.NODEFAULT:
        return "required"
    d = defaults[k]
    if isinstance(d, msgspec._core.Factory):  # type: ignore[attr-defined]
        d = d.factory()
    if isinstance(d, msgspec.Struct):
        return "(its table's defaults)"
    if d is None:
        return "none"
    return f"`{d!r}`" if not isinstance(d, str) else f'`"{d}"`'


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def reference_markdown() -> str:
    """The reference, as MyST Markdown."""
    from zswarm.scenario.algorithm import SENSORS, resolve
    from zswarm.scenario.faults import FAULT_KINDS
    from zswarm.util.plugins import registered

    out: list[str] = []
    for table, cls, note in _tables():
        out += [f"## `{table}`", ""]
        doc = inspect.getdoc(cls) or ""
        out += [doc.split("\n\n")[0].replace("\n", " "), ""]
        if note:
            out += [note, ""]
        comments = _comments(cls)
        hints = typing.get_type_hints(cls, include_extras=True)
        out += ["| key | type | default | bounds | unit, meaning |", "|---|---|---|---|---|"]
        for name in cls.__struct_fields__:
            typ, b = _type(hints[name])
            out.append(f"| `{name}` | {_cell(typ)} | {_cell(_default(cls, name))} | {_cell(_bound_text(b))} | {_cell(comments.get(name, ''))} |")
        out.append("")
    out += ["## `[algorithm.gains]` of each shipped algorithm", "", "Each gain is a number > 0; one without a default must be given.", ""]
    out += ["| algorithm | gains (default) | sensors |", "|---|---|---|"]
    for name, module in sorted(registered("zswarm.algorithms", "agent.").items()):
        if not module.startswith("agent."):
            continue  # another package's: not shipped with zswarm
        spec = resolve(name)[0].SPEC
        gains = ", ".join(f"`{k}`" + (f" ({d:g})" if d is not None else " (required)") for k, d in spec.gains.items()) or "none"
        out.append(f"| `{name}` | {gains} | {', '.join(f'`{s}`' for s in sorted(spec.sensors))} |")
    out += ["", "## Lists the loader checks against", ""]
    out += [f"- sensors (`[world] sensors`): {', '.join(f'`{s}`' for s in SENSORS)}"]
    out += [f"- fault kinds (`[[faults]] kind`): {', '.join(f'`{k}`' for k in FAULT_KINDS)}"]
    out += ["", "The agents (`[[agents]]`), the graph and the faults are read by hand (rotations, expressions, the papers' graph assumptions): see [Scenario files](../scenarios.md)."]
    return "\n".join(out) + "\n"


GENERATED = "reference/scenario-tables.md"  # written at every build, never committed (.gitignore)


def _write(app: Any) -> None:
    """Write the reference beside the page that includes it, before Sphinx reads the sources."""
    from pathlib import Path

    path = Path(app.srcdir) / GENERATED
    text = reference_markdown()
    if not path.exists() or path.read_text() != text:  # unchanged: not rewritten, so not re-read
        path.write_text(text)


def _as_help_prints(text: str) -> Any:
    """A description, help or epilog as ``--help`` prints it: plain text (``|R̄_k|_I`` is not
    markup), an epilog of several lines (the examples and exit codes) as a literal block."""
    from docutils import nodes

    if "\n" in text.strip():
        return nodes.literal_block(text, text)
    if text.startswith("Default: ``") and text.endswith("``"):  # sphinx-argparse's own line, in its markup
        value = text[len("Default: ``") : -2]
        return nodes.paragraph("", "", nodes.Text("Default: "), nodes.literal(value, value))
    return nodes.paragraph(text, text)


def _plain_argparse() -> None:
    """sphinx-argparse reads every help text as reStructuredText; ours are plain text."""
    from docutils import nodes
    from sphinxarg import ext

    def render_list(items: list[Any], markdown_help: bool, settings: Any = None) -> list[Any]:
        out: list[Any] = []
        for e in items:
            if isinstance(e, str):
                out.append(_as_help_prints(e))
            elif isinstance(e, nodes.definition):
                out += e
        return out

    ext.render_list = render_list
    ext.ArgParseDirective._nested_parse_paragraph = lambda self, text: _as_help_prints(text)


def setup(app: Any) -> dict[str, Any]:
    _plain_argparse()
    app.connect("builder-inited", _write)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
