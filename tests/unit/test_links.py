"""Link models (zswarm/scenario/links.py) against their distributions.

Statistical checks use N = 20 000 messages and 4-sigma bands (a false
failure about once in 16 000 runs; the seeds are fixed anyway, so these are
deterministic).
"""

import math

import numpy as np
import pytest

from zswarm.scenario.links import PURPOSES, LinkDraws, LinkModel, LinkSpec, block, link_seed

N = 20_000


def releases(spec, name="1->3", seed=1, dt=0.01):
    m = LinkModel(spec, name, seed)
    return m, [m.admit(k * dt) for k in range(N)]


def test_zero_spec_is_the_identity_and_draws_nothing():
    m, rel = releases(LinkSpec())
    assert rel == [k * 0.01 for k in range(N)]
    assert m.draws.rngs == {}


@pytest.mark.parametrize("p", [0.05, 0.3, 0.5])
def test_bernoulli_drop_ratio(p):
    m, rel = releases(LinkSpec(drop=p))
    lost = sum(r is None for r in rel) / N
    assert abs(lost - p) < 4 * math.sqrt(p * (1 - p) / N)
    assert m.dropped == sum(r is None for r in rel)


def test_gilbert_elliott_loss_and_burst_length():
    spec = LinkSpec(ge_p_gb=0.02, ge_p_bg=0.2, ge_loss_good=0.0, ge_loss_bad=1.0)
    _, rel = releases(spec)
    lost = np.array([r is None for r in rel])
    assert spec.stationary_loss == pytest.approx(0.02 / 0.22)
    assert lost.mean() == pytest.approx(spec.stationary_loss, abs=0.02)  # bursts: fewer independent samples, wider band
    runs, n = [], 0
    for x in lost:
        if x:
            n += 1
        elif n:
            runs.append(n)
            n = 0
    assert np.mean(runs) == pytest.approx(1 / 0.2, rel=0.15)  # mean burst 1/p_bg messages


def test_constant_delay_and_fifo():
    _, rel = releases(LinkSpec(delay_ms=50.0))
    assert all(r == pytest.approx(k * 0.01 + 0.05) for k, r in enumerate(rel))


@pytest.mark.parametrize("kind", ["normal", "exponential"])
def test_jitter_never_negative_and_fifo_unless_reordering(kind):
    _, rel = releases(LinkSpec(delay_ms=5.0, jitter_ms=20.0, jitter=kind))
    d = np.array(rel) - 0.01 * np.arange(N)
    assert d.min() >= 0
    assert np.all(np.diff(rel) >= 0)  # FIFO: nothing overtakes
    _, rel2 = releases(LinkSpec(delay_ms=5.0, jitter_ms=20.0, jitter=kind, reorder=True))
    d2 = np.array(rel2) - 0.01 * np.arange(N)
    assert d2.min() >= 0
    assert np.any(np.diff(rel2) < 0)  # with reordering some do
    if kind == "exponential":
        assert d2.mean() == pytest.approx(0.005 + 0.020, rel=0.05)
    else:
        assert np.median(d2) == pytest.approx(0.005, abs=0.001)


def test_seeded_per_link_and_reproducible():
    a = releases(LinkSpec(drop=0.3, jitter_ms=5.0), name="1->3")[1]
    b = releases(LinkSpec(drop=0.3, jitter_ms=5.0), name="1->3")[1]
    c = releases(LinkSpec(drop=0.3, jitter_ms=5.0), name="2->3")[1]
    assert a == b and a != c


@pytest.mark.parametrize(
    "spec, field",
    [
        (LinkSpec(delay_ms=-1.0), "delay_ms"),
        (LinkSpec(jitter_ms=float("nan")), "jitter_ms"),
        (LinkSpec(drop=1.5), "drop"),
        (LinkSpec(ge_p_gb=-0.1), "ge_p_gb"),
        (LinkSpec(ge_p_gb=0.1, ge_p_bg=0.0), "ge_p_bg"),
        (LinkSpec(jitter="uniform"), "jitter"),
    ],
)
def test_bad_specs_are_named(spec, field):
    assert [f for f, _ in spec.check()] == [field]
    assert LinkSpec().check() == []


@pytest.mark.parametrize("purpose, jitter", [("drop", "normal"), ("jitter", "normal"), ("jitter", "exponential")])
def test_a_stream_read_in_blocks_is_the_stream_read_one_at_a_time(purpose, jitter):
    """The batched engine reads a link's streams in blocks of its own size, sim in BLOCK:
    the same numbers either way, bit for bit (numpy fills a block one variate at a time)."""
    seed = link_seed(7, "1->3", purpose)
    rng = np.random.default_rng(seed)
    one = [float(block(rng, purpose, jitter, 1)[0]) for _ in range(1000)]
    for size in (7, 256, 1000):
        rng = np.random.default_rng(seed)
        got = np.concatenate([block(rng, purpose, jitter, size) for _ in range(-(-1000 // size))])[:1000]
        assert np.array_equal(got, np.array(one))


def test_a_message_takes_its_own_numbers_whatever_became_of_the_others():
    """Message n takes the n-th number of each stream its spec uses, lost or not: the
    losses and delays of a link with loss are those of the same link without it, message by
    message, where the lossy one delivers (what lets the batched engine read ahead)."""
    lossy = LinkSpec(delay_ms=5.0, jitter_ms=3.0, drop=0.3, ge_p_gb=0.05, ge_p_bg=0.3, reorder=True)
    jitter_only = LinkSpec(delay_ms=5.0, jitter_ms=3.0, reorder=True)
    _, a = releases(lossy)
    _, b = releases(jitter_only)
    kept = [k for k, r in enumerate(a) if r is not None]
    # Kept: (1 − 0.3)·(1 − π_bad), π_bad = 0.05/0.35 (ge_loss_bad = 1): 0.60 of N.  Bursts of mean
    # 1/0.3 messages widen the binomial σ = √(0.24/N) ≈ 0.0035 by at most ~√(2·3.3): σ < 0.01, so
    # [0.5, 0.8] is over 10σ either side: it checks the losses happened, not their rate.
    assert 0.5 * N < len(kept) < 0.8 * N
    assert all(a[k] == b[k] for k in kept)
    d = LinkDraws(lossy, "1->3", 1)
    assert set(d.next()) == set(PURPOSES)


@pytest.mark.parametrize(
    "spec",
    [
        LinkSpec(delay_ms=3.0),
        LinkSpec(drop=0.2),
        LinkSpec(delay_ms=2.0, jitter_ms=4.0),
        LinkSpec(delay_ms=2.0, jitter_ms=4.0, jitter="exponential", reorder=True),
        LinkSpec(delay_ms=1.0, jitter_ms=2.0, drop=0.1, ge_p_gb=0.05, ge_p_bg=0.3, ge_loss_good=0.01, ge_loss_bad=0.9),
    ],
)
def test_the_batched_engines_link_is_each_draws_sim_link(spec):
    """agent/batched_links.py LinkStack admits a message for M draws at once: each draw's
    releases and losses are, bit for bit, those of LinkModel with that draw's seed (the same
    streams, read AHEAD at a time, the same operations element by element)."""
    from agent.batched_links import AHEAD, LinkStack

    _same_as_models(LinkStack, AHEAD, [spec] * 4)


def test_draws_of_one_batch_may_have_links_of_their_own():
    """A sweep over link parameters steps its points in one batch: each draw its own spec (a
    perfect link, a delay, each jitter, loss, bursts, cuts), each still its sim run's link."""
    from agent.batched_links import AHEAD, LinkStack

    _same_as_models(LinkStack, AHEAD, [LinkSpec(), LinkSpec(delay_ms=3.0), LinkSpec(delay_ms=2.0, jitter_ms=4.0, jitter="exponential", reorder=True), LinkSpec(delay_ms=1.0, jitter_ms=2.0, drop=0.1, ge_p_gb=0.05, ge_p_bg=0.3, cuts=((1.0, 2.5),)), LinkSpec(drop=0.5), LinkSpec(cuts=((0.5, 1.0), (3.0, 3.2)))])


def _same_as_models(LinkStack, AHEAD, specs):  # the class and constant, imported late

    seeds = [3, 4, 11, 2**62 + 5, 9, 10][: len(specs)]
    stack = LinkStack(specs, "2->world", seeds)
    models = [LinkModel(sp, "2->world", s) for sp, s in zip(specs, seeds, strict=True)]
    n = AHEAD + 300  # across a block boundary of both
    for k in range(n):
        t = k * 0.01
        got = stack.admit(t)
        want = [m.admit(t) for m in models]
        assert [None if math.isnan(g) else float(g) for g in got] == want, k
    assert stack.dropped.tolist() == [m.dropped for m in models] and stack.offered.tolist() == [n] * len(specs)
    assert stack.cut.tolist() == [m.cut for m in models]
    assert any(s.cuts for s in specs) <= (stack.cut.sum() > 0)


@pytest.mark.parametrize("specs", [[LinkSpec(delay_ms=1.0, jitter_ms=2.0, drop=0.1, ge_p_gb=0.05, ge_p_bg=0.3)] * 5, [LinkSpec(), LinkSpec(delay_ms=2.0, jitter_ms=4.0, jitter="exponential", reorder=True), LinkSpec(drop=0.5, cuts=((1.0, 2.5),)), LinkSpec(delay_ms=3.0), LinkSpec(jitter_ms=1.0)]])
def test_draws_that_send_at_ticks_of_their_own_each_take_their_own_numbers(specs):
    """Agents whose sensor links lose packets step (and command) at ticks of their own, so a
    draw's n-th command is sent when the others' are not: LinkStack.admit with ``rows`` gives
    each of those draws its sim link's release for its own next message, first after messages
    of every draw (one count for all), then across each draw's own block boundaries."""
    from agent.batched_links import AHEAD, LinkStack

    seeds = [3, 4, 11, 2**62 + 5, 9]
    stack = LinkStack(specs, "2->world", seeds)
    models = [LinkModel(sp, "2->world", s) for sp, s in zip(specs, seeds, strict=True)]
    rng = np.random.default_rng(0)
    sent = np.zeros(len(specs), dtype=int)
    for k in range(2 * AHEAD + 200):
        t = k * 0.01
        rows = None if k < 40 else np.flatnonzero(rng.random(len(specs)) < (0.9, 0.5, 0.7, 0.95, 0.3))
        got = stack.admit(t, rows)
        idx = np.arange(len(specs)) if rows is None else rows
        want = [models[m].admit(t) for m in idx]
        assert [None if math.isnan(g) else float(g) for g in got] == want, k
        sent[idx] += 1
    assert sent.min() < AHEAD < sent.max()  # some draws crossed a block boundary, others not yet
    assert stack.offered.tolist() == sent.tolist() and stack.dropped.tolist() == [m.dropped for m in models]
