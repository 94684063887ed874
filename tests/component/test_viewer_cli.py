"""Bad input to the viewer and compose commands: a clear one-line error, exit 2,
nothing started and nothing written."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import ROOT, TOPO
from zswarm.transport import procutil


def zswarm(*args: str, cwd=ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "zswarm", *args], capture_output=True, text=True, cwd=cwd, timeout=60)


@pytest.mark.parametrize(
    "args, match",
    [
        (["compose", "nope.toml"], "nope.toml"),
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--set", "links.drop=0.1"], "--set needs -o FILE"),
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--build-context", "/tmp"], "no Dockerfile there"),
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--network", "mesh"], "invalid choice: 'mesh'"),
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--set", "links.drop=1.5", "-o", "/tmp/x.yml"], "links.drop: must be a probability"),
        (["run", str(TOPO / "thesis-3.2-fixed8.toml"), "--live", "8765"], "expected HOST:PORT"),
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--live", "8765"], "expected HOST:PORT"),  # one spelling of --live everywhere
        (["compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--live", "127.0.0.1:0"], "a port for Docker to publish"),
        (["record", str(TOPO / "thesis-3.2-fixed8.toml"), "--live", "8765"], "expected HOST:PORT"),
        (["echo", "est//3", "--connect", "tcp/127.0.0.1:9"], "est//3: not a key expression"),
        (["hz", "est/3/", "--connect", "tcp/127.0.0.1:9"], "est/3/: not a key expression"),
        (["echo", "est/3", "--run-id", "bad id!", "--connect", "tcp/127.0.0.1:9"], "--run-id: run id must match"),
        (["hz", "est/3", "--results", "/nonexistent"], "no running zswarm run there"),
        (["echo", "est/3"], "a client needs --connect"),
        (["replay", str(ROOT / "topologies")], "no recording there"),
        (["replay", "--speed", "0", str(ROOT)], "must be > 0"),
    ],
)
def test_bad_input_exits_2_with_the_reason(args, match, tmp_path):
    r = zswarm(*args, cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert match in r.stderr, r.stderr
    assert not list(tmp_path.iterdir())


def test_replay_needs_somewhere_to_play(tmp_path):
    (tmp_path / "recording.mcap").write_bytes(b"")
    r = zswarm("replay", str(tmp_path), cwd=tmp_path)
    assert r.returncode == 2 and "needs --live [HOST:PORT] or a Zenoh endpoint" in r.stderr, r.stderr


@pytest.mark.parametrize("text, want", [("127.0.0.1:8765", ("127.0.0.1", 8765)), ("[::1]:0", ("::1", 0)), ("0.0.0.0:65535", ("0.0.0.0", 65535))])
def test_host_port(text, want):
    assert procutil.host_port(text) == want


@pytest.mark.parametrize("text", ["8765", ":8765", "host:", "host:http", "host:65536"])
def test_host_port_rejects(text):
    with pytest.raises(Exception, match="expected HOST:PORT"):
        procutil.host_port(text)


def test_compose_to_stdout_names_every_process():
    r = zswarm("compose", str(TOPO / "decarli-8-formation.toml"), "--network", "routed", "--no-build", "--image", "zswarm:test")
    assert r.returncode == 0, r.stderr
    for name in ["router", "router-agents", "recorder", "world", *(f"agent{i}" for i in range(1, 9))]:
        assert f"\n  {name}:\n" in r.stdout, name
    assert "build:" not in r.stdout and r.stdout.count('image: "zswarm:test"') == 12
    assert r.stdout.count("internal: true") == 2


def test_compose_live_publishes_the_given_host_and_port():
    """``--live [HOST:PORT]`` as run and record spell it: the recorder listens in its container,
    Docker publishes HOST:PORT (the default 127.0.0.1:8765 without a value)."""
    r = zswarm("compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--no-build", "--image", "zswarm:test", "--live", "0.0.0.0:9000")
    assert r.returncode == 0, r.stderr
    assert 'ports: ["0.0.0.0:9000:9000"]' in r.stdout and '"--live", "0.0.0.0:9000"]' in r.stdout
    d = zswarm("compose", str(TOPO / "thesis-3.2-fixed8.toml"), "--no-build", "--image", "zswarm:test", "--live")
    assert d.returncode == 0 and 'ports: ["127.0.0.1:8765:8765"]' in d.stdout
