#!/usr/bin/env bash
# make test: the test layers in the order and on the cores that fit a 2-core machine.
#
# 1. Unit and component tests on four workers (by file), and the tests of real processes that need
#    no real time kept (marker "processes": the kill -9 nemeses, the Dask cluster, the Zenoh fuzz,
#    docker-compose config of the shipped scenarios):
#    CPU-bound, each of their waits a hang's deadline, so they share the machine with the component
#    tests rather than lengthen the real-time stream of step 2 (629 s of its 1885 on 2026-12-07,
#    beside stress-ng --cpu 1).
# 2. The integration tests alone (their processes keep real time), and beside them, at idle
#    priority, the component tests marked "background" (tests/conftest.py: long `sim` runs that
#    keep no time and have no wall-clock limit).  `chrt --idle 0` (SCHED_IDLE): a waking process
#    of a run preempts them at once, and in their own session they get only CPU that no other
#    process of it asks for.  Between sessions it does not reach: the kernel's autogroup
#    scheduling (kernel.sched_autogroup_enabled, on in Debian's kernels) shares the CPU between
#    sessions first, so the part gets a session's share, as each process of a run (each in a
#    session of its own) does, of which a run's process needs a small part.  Measured on
#    2026-12-07 on one core: a SCHED_IDLE busy loop in a session of its own ran 14.9 M
#    iterations beside a normal one's 14.3 M in another session, and 0.9 M beside 14.9 M in the
#    same session.  Their output follows the integration layer's.
#
# 1b. (In the background part of step 2.)  The tests whose verdict depends on the rounding of the machine (the golden sim runs, the
#    compiled loops against numpy, sin and cos, SO(3)) once more as on another machine: OpenBLAS
#    forced to its Prescott kernel (no FMA: it rounds 3x3 products otherwise than the
#    SkylakeX/Haswell/Zen kernels), numpy's AVX-512 paths off (other arctan2 and exp) and glibc's
#    libm without FMA.  All are run-time switches, nothing to install; a verdict that holds on one machine only is
#    caught here.  The batched engine's agreement with sim runs so too.
#
# Each part lists its slowest tests (where the suite's time goes, on CI's machine too).  The exit
# status is 0 only if every part passed.  Ctrl-C (or SIGTERM) stops both parts of step 2: the
# background part runs in a session of its own (so a terminal's Ctrl-C does not reach it, and a
# shell starts it with SIGINT ignored), terminated as a whole (SIGTERM to its process group: pytest
# and its workers) and waited for.
set -u
PY=${1:-.venv/bin/python}

# Every process of the suite (a run starts a dozen, a sweep one per run) imports zswarm; where
# PYTHONDONTWRITEBYTECODE is set (it is on the machines this project is developed on) none writes its bytecode,
# and each compiled the sources again: 0.5-1.2 s of CPU more per command (measured 2026-12-07:
# a 2 s run 8.1 s -> 6.9 s, a 4-run sim sweep 6.4 s -> 5.8 s).  compileall writes it whatever
# that variable says, and only where a source is newer than its bytecode.
"$PY" -m compileall -q zswarm agent world tests >/dev/null || exit $?

# Each worker in a session of its own (tests/conftest.py, ZSWARM_WORKER_SESSIONS): beside another
# session's busy process, two workers get two thirds of the two cores, not one core between them
# (the kernel shares the CPU between sessions first).
# Four workers on the two cores: a worker often waits (for a sweep's or a nemesis' processes, a
# pause of the fuzz), and then another has the core.  Measured 2026-12-07 beside stress-ng --cpu 1
# (this layer alone, 916 tests): 699 s with 2 workers (1.1 cores used), 628 s with 3 (1.33),
# 583 s with 4 (1.42).  Its tests keep no real time: each wait of theirs is a hang's deadline.
# --no-loadscope-reorder: the files in collection order, the longest first (tests/conftest.py LONG_FIRST).
ZSWARM_WORKER_SESSIONS=1 "$PY" -m pytest -q -m "not integration and not background" -n 4 --dist loadfile --no-loadscope-reorder --durations=15 || exit $?

# What numpy 1.x and 2.x call their AVX-512 dispatch targets; a name a numpy does not know is ignored.
# glibc's libm without its FMA builds of exp, sin, cos, atan2 (GLIBC_TUNABLES): other bits on the
# same CPU.  tests/data/golden_spread.json measured this combination (make golden-spread), and
# test_golden_sim checks that the suite's settings are among those measured.
OTHER="OPENBLAS_CORETYPE=Prescott GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA NPY_DISABLE_CPU_FEATURES=AVX512F,AVX512CD,AVX512_SKX,AVX512_CLX,AVX512_CNL,AVX512_ICL,AVX512_SPR,X86_V4"

idle=(nice -n 19)
command -v chrt >/dev/null 2>&1 && idle=(chrt --idle 0)
log=$(mktemp)
# The background part: its tests, then step 1b (the rounding-sensitive files, and the batched engine's
# agreement with sim on its noisy schemes and the §4.5 continuous observer, a third of test_batched)
# as on another machine: CPU-bound, no real time, off the critical path (the first part: 22 s on two
# cores beside stress-ng, when it ran after step 1).
export PY OTHER
setsid "${idle[@]}" bash -c '
    "$PY" -m pytest -q -m "background and not integration" -n 2 --dist loadfile --durations=15 || exit $?
    echo "--- the rounding-sensitive tests again as on another machine: $OTHER"
    env $OTHER "$PY" -m pytest -q -n 2 --dist loadfile -p no:cacheprovider tests/component/test_golden_sim.py tests/unit/test_kernels.py tests/unit/test_trig.py tests/unit/test_so3.py || exit $?
    env $OTHER "$PY" -m pytest -q -n 2 -p no:cacheprovider tests/component/test_batched.py -k "noisy or continuous5"
' >"$log" 2>&1 &
bg=$!

show_background() {
    echo "--- the background tests (${idle[*]}, beside the integration layer): exit $1"
    cat "$log"
    rm -f "$log"
}
stop_background() {
    kill -TERM -- "-$bg" 2>/dev/null
    wait "$bg"
    show_background "$?"
}
trap 'stop_background; exit 130' INT
trap 'stop_background; exit 143' TERM

# A real-time run that did not keep up cannot make the checks it exists for: they raise
# tests.keepup.MachineDidNotKeepUp, and a test that failed with that exception and nothing else
# runs again, twice at most (tests/keepup.py: the decision is on the exception's type, never on
# a message's text).  Any other failure fails at once; a test still overloaded on its third try
# fails, naming the check.  -rR lists each rerun with its reason.
RERUN=(-rR)
echo "$PY -m pytest -q -m integration --durations=15 ${RERUN[*]}   (beside it: pytest -m background at ${idle[*]}, its output below)"
"$PY" -m pytest -q -m integration --durations=15 "${RERUN[@]}"
it=$?
wait "$bg"
bt=$?
trap - INT TERM
show_background "$bt"
exit $((it != 0 || bt != 0))
