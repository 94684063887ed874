"""The suite's rule for runs that could not keep up, and for skips (a pytest plugin, loaded by
tests/conftest.py).

**Reruns.**  A real-time run on a busy machine may fall behind its schedule; its numbers are then
not the equations' alone, and a check made on them would judge the machine, not the code.  Such a
check raises :class:`MachineDidNotKeepUp` (tests/integration/conftest.py: ``fail_if_overloaded``,
``require_kept_up``), and a test that failed with that exception, and with nothing else, runs
again, twice at most.  The decision is on the exception's type, never on text: an assertion that
fails beside a launcher log saying "did not keep up" fails at once (tests/unit/test_keepup.py
plants one).  A test still overloaded on its third try fails, naming the check it could not make.
Every rerun is listed at the end with its reason (``make test`` passes ``-rR`` too).

**Skips.**  A skipped test is a failure, wherever the suite runs: the tests that could skip are
those whose real part (a Docker engine, network namespaces, Chromium) could not be had, and a green
with one of them skipped would say that the part works when nothing checked it.  Module-level
skips and ``importorskip`` (a skipped collection) count too.  The one way to skip is the marker
``cannot_exist_here(reason)`` on a test whose part cannot exist on this kind of machine: it skips,
saying why (no test carries it today).
"""

from __future__ import annotations

import pytest

RERUNS = 2  # a test overloaded three times running fails: the machine is too busy for its check
CANNOT_EXIST_HERE = "cannot_exist_here"


class MachineDidNotKeepUp(Exception):
    """A check that a real-time run could not make because this machine did not keep up with it
    (summary.json ``overload``); the test runs again (:data:`RERUNS` times at most)."""


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{CANNOT_EXIST_HERE}(reason): this test's real part cannot exist on this kind of machine: it skips, saying why")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # pytest-rerunfailures reruns a test only when every failing phase (setup, call, teardown)
    # failed with this type: a leak found at teardown beside an overloaded call fails at once.
    # ``only_rerun`` matches the type anywhere in an exception's chain (its ``__context__`` too:
    # an assertion raised while handling an overload); ``rerun_except``, which skips contexts,
    # makes the failure itself the type: it fails at once on every exception whose type's name
    # (what the plugin's text for an exception starts with) is another's.  Its ``condition``
    # argument is not used: with it, a teardown failure beside a matching call went unreported.
    rerun = pytest.mark.flaky(reruns=RERUNS, only_rerun=[MachineDidNotKeepUp], rerun_except=[rf"^(?!{MachineDidNotKeepUp.__name__}: )"])
    for item in items:
        item.add_marker(rerun)


def pytest_runtest_setup(item: pytest.Item) -> None:
    mark = item.get_closest_marker(CANNOT_EXIST_HERE)
    if mark is not None:
        why = mark.args[0] if mark.args else mark.kwargs.get("reason", "")
        assert why, f"{item.nodeid}: {CANNOT_EXIST_HERE} needs the reason its part cannot exist on this kind of machine"
        pytest.skip(f"cannot exist on this kind of machine: {why}")


def _allowed(item: pytest.Item | None) -> bool:
    return item is not None and item.get_closest_marker(CANNOT_EXIST_HERE) is not None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> object:
    outcome = yield
    rep = outcome.get_result()
    if rep.skipped and not hasattr(rep, "wasxfail") and not _allowed(item):
        reason = rep.longrepr[2] if isinstance(rep.longrepr, tuple) else str(rep.longrepr)
        rep.outcome = "failed"
        rep.longrepr = f"a skip is a failure (tests/keepup.py): every real part this test needs must be here: {reason}"
    return None


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> object:
    outcome = yield
    rep = outcome.get_result()
    if rep.skipped:  # a module-level skip or an importorskip: the whole file is unchecked
        reason = rep.longrepr[2] if isinstance(rep.longrepr, tuple) else str(rep.longrepr)
        rep.outcome = "failed"
        rep.longrepr = f"a skipped module is a failure (tests/keepup.py): {reason}"
    return None


def pytest_terminal_summary(terminalreporter) -> None:
    """The tests run again because the machine did not keep up, each with its reason."""
    reruns = terminalreporter.stats.get("rerun", [])
    if not reruns and not any("tests/integration/" in r.nodeid for cat in terminalreporter.stats.values() for r in cat if hasattr(r, "nodeid")):
        return
    terminalreporter.write_line(f"tests run again because this machine did not keep up: {len(reruns)}")
    for r in reruns:
        crash = getattr(r.longrepr, "reprcrash", None)
        why = crash.message if crash is not None else str(r.longrepr).strip().splitlines()[-1]
        terminalreporter.write_line(f"  {r.nodeid}: {why[:300]}")
