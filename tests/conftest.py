from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOPO = ROOT / "topologies"


@pytest.fixture
def fixed8_text() -> str:
    return (TOPO / "thesis-3.2-fixed8.toml").read_text()
