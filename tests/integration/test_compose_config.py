"""The compose files zswarm writes, checked without running them: the shipped
docker-compose.yml is the generator's, and ``docker-compose config`` accepts the file of every
shipped scenario on both network layouts.  Real processes (``zswarm compose``, docker-compose)
but no run: marker ``processes``, in make test's first layer.  The runs in a real Docker engine
are tests/integration/test_compose.py."""

from __future__ import annotations

import sys

import pytest

from tests.conftest import ROOT, TOPO
from tests.integration.dockerbase import compose_command
from tests.integration.dockerbase import run as _run
from zswarm.engines import compose
from zswarm.scenario import load

pytestmark = pytest.mark.processes


@pytest.fixture(scope="module")
def compose_cli():
    """The docker-compose command (installed if missing)."""
    return compose_command()


def test_shipped_compose_file_is_the_generators():
    """docker-compose.yml is `zswarm compose topologies/thesis-3.2-fixed8.toml -o docker-compose.yml`."""
    sc = load(TOPO / "thesis-3.2-fixed8.toml")
    want = compose.write(
        sc, TOPO / "thesis-3.2-fixed8.toml", ROOT / "docker-compose.yml", "zswarm:latest", ROOT, None, "compose", "${ZSWARM_RESULTS:-./runs}", "flat", None, 1.0, None, None,
        argv=["topologies/thesis-3.2-fixed8.toml", "-o", "docker-compose.yml"],
    )  # fmt: skip
    assert (ROOT / "docker-compose.yml").read_text() == want


@pytest.mark.parametrize("network", ["flat", "routed"])
def test_compose_file_of_every_shipped_scenario_passes_config(compose_cli, tmp_path, network):
    """`docker-compose config` accepts the file of every scenario in topologies/."""
    names = sorted(p.stem for p in TOPO.glob("*.toml"))
    assert len(names) >= 10
    for name in names:
        out = tmp_path / f"{name}.yml"
        r = _run([sys.executable, "-m", "zswarm", "compose", str(TOPO / f"{name}.toml"), "-o", str(out), "--network", network, "--live", "127.0.0.1:8765"], 60, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        r = _run([compose_cli, "-f", str(out), "config", "-q"], 60, cwd=tmp_path)
        assert r.returncode == 0, f"{name}: {r.stderr}"
        sc = load(TOPO / f"{name}.toml")
        text = out.read_text()
        assert all(f"  agent{i}:" in text for i in sc.ids), name
