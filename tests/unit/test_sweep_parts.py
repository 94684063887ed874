"""The pieces of ``zswarm sweep``: value lists, convergence time, resuming from sweep.csv."""

import numpy as np
import pytest

from zswarm.report import convergence_time
from zswarm.scenario import ScenarioError
from zswarm.studies.sweep import parse_vary, read_done, split_values


def test_values_lists_and_ranges():
    assert split_values("0,50,100") == ["0", "50", "100"]
    assert split_values("0:200:50") == ["0", "50", "100", "150", "200"]
    assert split_values("0:0.5:0.1") == ["0", "0.1", "0.2", "0.3", "0.4", "0.5"]  # no 0.30000000000000004
    assert split_values("[1,0,0],[0,1,0]") == ["[1,0,0]", "[0,1,0]"]
    assert split_values('"normal","exponential"') == ['"normal"', '"exponential"']
    with pytest.raises(ValueError):
        split_values("0,,1")
    with pytest.raises(ValueError):
        split_values("5:0:1")


def test_parse_vary_canonical_field_and_errors():
    v = parse_vary('links.per_link."1->3".drop=0,0.5')
    assert v.field == 'links.per_link."1->3".drop' and v.values == ("0", "0.5")
    with pytest.raises(ScenarioError, match="expected FIELD=v1,v2"):
        parse_vary("links.drop")


def test_convergence_time_is_the_first_time_after_which_it_stays_below():
    t = np.arange(0, 10, 1.0)
    v = np.array([5, 3, 0.5, 2, 0.5, 0.4, 0.3, 0.2, 0.1, 0.05])
    assert convergence_time(t, v, 1.0) == 4.0  # dips below at 2 s but comes back above at 3 s
    assert convergence_time(t, v, 10.0) == 0.0
    assert convergence_time(t, v, 0.01) is None  # not below at the end: never converged
    v2 = v.copy()
    v2[6] = np.nan  # no estimate at that time counts as not converged
    assert convergence_time(t, v2, 1.0) == 7.0


def test_read_done_ignores_a_torn_last_row(tmp_path):
    p = tmp_path / "sweep.csv"
    p.write_text("run_id,point,status\np000-r0,0,ok\np000-r1,0,failed\np001-r0,1,o")
    assert set(read_done(p)) == {"p000-r0", "p000-r1"}
