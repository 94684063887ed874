"""tests/keepup.py, the suite's rule for overloaded runs and skips, on planted tests run by an
inner pytest (pytester): a rerun only for MachineDidNotKeepUp, whatever a message says; a skip
of any kind is a failure."""

from __future__ import annotations

import pytest

from tests.conftest import ROOT
from tests.keepup import RERUNS

# Every planted file imports the real exception type from the real plugin module.
HEAD = "import pytest\nfrom tests.keepup import MachineDidNotKeepUp\n"
# What the launcher prints on an overloaded run (zswarm/report/table.py), as a failing test's
# message may carry it inside a log.
OVERLOAD_LOG = "OVERLOADED: 3 of 8 agents missed more than 2 % of their ticks: this machine did not keep up, so the errors are not the algorithm's alone"


def run(pytester: pytest.Pytester, src: str) -> pytest.RunResult:
    pytester.makepyfile(test_planted=HEAD + src)
    return pytester.runpytest("-p", "tests.keepup", "-p", "no:cacheprovider", "-rRs")


def run_apart(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, src: str) -> pytest.RunResult:
    """As :func:`run`, in a pytest process of its own (the repository on its path): the planted
    file imports tests/integration/conftest.py, whose numpy an inner pytest in this process cannot
    import a second time."""
    pytester.makepyfile(test_planted=HEAD + src)
    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    return pytester.runpytest_subprocess("-p", "tests.keepup", "-p", "no:cacheprovider", "-rRs")


def outcomes(r: pytest.RunResult, **want: int) -> None:
    """The inner run's counts are ``want`` (0 for the ones not named), reruns included."""
    got = r.parseoutcomes()
    keys = {"passed", "failed", "skipped", "errors", "rerun"} | set(want)
    assert {k: got.get(k, 0) for k in keys} == {k: want.get(k, 0) for k in keys}, r.stdout.str()


def test_a_real_failure_beside_an_overload_message_fails_at_once(pytester):
    # An assertion whose message embeds the launcher's log, overload phrase and all: the text
    # matched --only-rerun before; now it is not the type, so it fails on its first try.
    r = run(pytester, f"""
calls = []
def test_planted():
    calls.append(1)
    log = {OVERLOAD_LOG!r}
    assert len(calls) > 5, f"exit code 1; launcher log: {{log}}"
""")
    outcomes(r, failed=1, rerun=0)
    assert "exit code 1; launcher log: OVERLOADED" in r.stdout.str()


def test_an_overloaded_run_reruns_and_passes_once_it_keeps_up(pytester):
    r = run(pytester, """
calls = []
def test_planted():
    calls.append(1)
    if len(calls) <= 2:
        raise MachineDidNotKeepUp("this machine did not keep up with the run (x), so the step rates could not be checked")
""")
    outcomes(r, passed=1, rerun=2)
    assert "tests run again because this machine did not keep up: 2" in r.stdout.str()
    assert "the step rates could not be checked" in r.stdout.str()  # each rerun's reason listed


def test_a_check_never_made_fails_after_its_reruns_naming_it(pytester):
    r = run(pytester, """
def test_planted():
    raise MachineDidNotKeepUp("this machine did not keep up with the run (x), so the command rates could not be checked")
""")
    outcomes(r, failed=1, rerun=RERUNS)
    assert "MachineDidNotKeepUp: this machine did not keep up with the run (x), so the command rates could not be checked" in r.stdout.str()


def test_a_real_failure_after_an_overloaded_try_is_not_rerun(pytester):
    # First try overloaded (rerun), second a real failure: it fails there, not a third time.
    r = run(pytester, """
calls = []
def test_planted():
    calls.append(1)
    if len(calls) == 1:
        raise MachineDidNotKeepUp("not kept up")
    assert False, "a real defect"
""")
    outcomes(r, failed=1, rerun=1)


def test_a_leak_at_teardown_beside_an_overloaded_call_fails_at_once(pytester):
    # Every failing phase must be the overload for a rerun: a fixture's own check failing at
    # teardown (processes left behind) is a defect whatever the call did.
    r = run(pytester, """
@pytest.fixture
def procs():
    yield
    assert False, "processes left behind: [1234]"
def test_planted(procs):
    raise MachineDidNotKeepUp("not kept up")
""")
    assert r.parseoutcomes().get("rerun", 0) == 0, r.stdout.str()
    assert "processes left behind: [1234]" in r.stdout.str()


def test_an_assertion_raised_while_handling_an_overload_is_a_real_failure(pytester):
    # pytest-rerunfailures' type filter follows an exception's context; the failure itself must
    # be the overload (keepup._only_overload), not an assertion raised in its except block.
    r = run(pytester, """
def test_planted():
    try:
        raise MachineDidNotKeepUp("not kept up")
    except MachineDidNotKeepUp:
        assert False, "a real defect found while handling it"
""")
    outcomes(r, failed=1, rerun=0)


@pytest.mark.parametrize(
    "src",
    [
        "def test_planted():\n    pytest.skip('no Docker engine')\n",
        "@pytest.mark.skipif(True, reason='no netns')\ndef test_planted():\n    pass\n",
        "pytest.skip('no Chromium', allow_module_level=True)\ndef test_planted():\n    pass\n",
        "np = pytest.importorskip('a_module_that_is_not_installed')\ndef test_planted():\n    pass\n",
    ],
    ids=["skip-in-test", "skipif", "module-level-skip", "importorskip"],
)
def test_every_kind_of_skip_is_a_failure(pytester, src):
    r = run(pytester, src)
    o = r.parseoutcomes()
    assert o.get("skipped", 0) == 0 and (o.get("failed", 0) + o.get("errors", 0)) == 1, r.stdout.str()
    assert r.ret != 0
    assert "is a failure (tests/keepup.py)" in r.stdout.str()


def test_a_test_whose_part_cannot_exist_here_skips_saying_why(pytester):
    r = run(pytester, """
@pytest.mark.cannot_exist_here("needs a GPU, which this kind of machine never has")
def test_planted():
    assert False
""")
    outcomes(r, skipped=1)
    assert "cannot exist on this kind of machine: needs a GPU" in r.stdout.str()


def test_an_exception_of_the_same_name_but_another_type_is_a_real_failure(pytester):
    # The decision is the type's, not its name's: a class of the same name elsewhere is not it.
    r = run(pytester, """
class MachineDidNotKeepUp(Exception):  # noqa: F811 (planted: the name without the type)
    pass
def test_planted():
    raise MachineDidNotKeepUp("not kept up")
""")
    outcomes(r, failed=1)


# A run's summary.json "overload" as results.overload writes it: kept up, or with late sensor data
# that the measured lateness accounts for (a machine short of CPU), or that it does not (a defect).
KEPT_UP = {"overloaded": False, "reasons": [], "late": [], "late_explained": True}
LATE = {"overloaded": False, "reasons": [], "late": ["7 of 7 agents found no new sensor packet at more than 2 % of their ticks"], "late_explained": True}
UNEXPLAINED = {**LATE, "late_explained": False}


@pytest.mark.parametrize(("overload", "want"), [(KEPT_UP, {"failed": 1}), (LATE, {"passed": 1, "rerun": 1}), (UNEXPLAINED, {"failed": 1})])
def test_a_check_of_the_equations_that_fails_on_late_data_reruns(pytester, monkeypatch, overload, want):
    """tests/integration/conftest.py judged_if_kept_up: a failed check reruns only when the run's
    sensor data came late for a reason its measured lateness gives; the second try keeps up and
    passes.  On a run that kept up, or late for no measured reason, the failure is final."""
    r = run_apart(pytester, monkeypatch, f"""
from tests.integration.conftest import judged_if_kept_up
calls = []
def test_planted():
    calls.append(1)
    s = {{"overload": {overload!r} if len(calls) == 1 else {KEPT_UP!r}}}
    with judged_if_kept_up(s, "the reconvergence"):
        assert len(calls) > 1, "reconverged in 9.9 s, bound 7.9 s"
""")
    outcomes(r, **want)
    if overload is LATE:
        assert "and the reconvergence failed on it: reconverged in 9.9 s, bound 7.9 s" in r.stdout.str()


@pytest.mark.parametrize(("overload", "problems", "rerun"), [(LATE, ["the recording has 2 holes"], True), (KEPT_UP, ["the recording has 2 holes"], False), (LATE, ["the recording has 2 holes", "agent 3 died"], False)])
def test_a_run_that_exited_on_a_hole_with_late_data_reruns(pytester, monkeypatch, overload, problems, rerun):
    """assert_run_exit_ok: exit 1 on holes alone, with late sensor data the lateness explains, is a
    machine that stood still (a rerun); a hole on a run that kept up, or beside another problem,
    fails at once."""
    r = run_apart(pytester, monkeypatch, f"""
import json
from tests.integration.conftest import assert_run_exit_ok
def test_planted(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({{"overload": {overload!r}, "problems": {problems!r}}}))
    (tmp_path / "launcher.log").write_text("NOT COMPLETED")
    assert_run_exit_ok(1, tmp_path, tmp_path / "launcher.log")
""")
    outcomes(r, failed=1, rerun=RERUNS if rerun else 0)
    assert ("MachineDidNotKeepUp: this machine did not keep up with the run" in r.stdout.str()) == rerun
