"""LinkCounter: loss from sequence gaps per incarnation, restarts followed at once, a stray
sequence number that cannot pin a link (issue 14)."""

from zswarm.scenario.links import RESYNC, LinkCounter


def feed(c, msgs):
    return [c.see(seq, inc, 0.001) for seq, inc in msgs]


def test_gaps_are_losses_and_a_late_message_is_recovered():
    c = LinkCounter()
    assert feed(c, [(0, 7), (1, 7), (4, 7)]) == [True, True, True]
    assert c.as_dict() | {} == {"delivered": 3, "dropped": 2, "reordered": 0, "latency_p50_ms": 1.0, "latency_p99_ms": 1.0}
    assert feed(c, [(3, 7)]) == [False]  # late: counted, not the newest
    assert (c.dropped, c.reordered) == (1, 1)


def test_a_restarted_sender_is_followed_at_once():
    """A neighbour restarted 5 s later numbers from 0 again: it used to be ignored until its
    seq passed the old one (agent 6 kept 5's pre-crash message for 17.7 s)."""
    c = LinkCounter()
    feed(c, [(s, 100) for s in range(3000)])
    assert feed(c, [(0, 200), (1, 200), (2, 200)]) == [True, True, True]
    d = c.as_dict()
    assert (d["delivered"], d["dropped"], d["reordered"], d["restarts"]) == (3003, 0, 0, 1)


def test_a_stray_sequence_number_cannot_pin_a_link():
    """One message with seq 2**53 − 1 (the wire's largest) under the sender's incarnation:
    the link follows the sender again after RESYNC messages, and the stray's gap is not
    counted as loss (it was 9e15 dropped, for the rest of the run)."""
    c = LinkCounter()
    feed(c, [(s, 5) for s in range(100)])
    assert feed(c, [(2**53 - 1, 5)]) == [True]
    got = feed(c, [(s, 5) for s in range(100, 100 + RESYNC + 5)])
    assert got == [False] * (RESYNC - 1) + [True] * 6
    d = c.as_dict()
    assert (d["delivered"], d["dropped"], d["reordered"], d["resyncs"]) == (100 + 1 + RESYNC + 5, 0, 0, 1)


def test_real_loss_across_a_resync_is_still_counted():
    c = LinkCounter()
    feed(c, [(s, 5) for s in range(10)])
    feed(c, [(10**9, 5)])
    feed(c, [(s, 5) for s in range(20, 20 + RESYNC)])  # 10..19 lost on the way
    feed(c, [(s, 5) for s in range(20 + RESYNC, 40)])
    assert c.dropped == 10 and c.resyncs == 1  # 10..19, and not the stray's gap
    feed(c, [(45, 5)])
    assert c.dropped == 15  # and gaps after it count again


def test_a_receiver_counts_from_the_first_message_it_sees():
    """A restarted receiver's first sensor packet has seq 3000: the 3000 before it were sent
    before it listened, not lost on the link (they read as 3000 dropped)."""
    c = LinkCounter()
    feed(c, [(s, 1) for s in range(3000, 3010)] + [(3012, 1)])
    assert (c.dropped, c.restarts) == (2, 0)


def test_reordering_is_not_taken_for_a_stray():
    """Emulated reordering puts a message ahead of a few older ones: ten of them arriving
    after it are reorders, not a reason to go back (a resync needs RESYNC_GAP)."""
    c = LinkCounter()
    feed(c, [(s, 1) for s in range(100)])
    assert feed(c, [(111, 1)] + [(s, 1) for s in range(100, 111)]) == [True] + [False] * 11
    assert (c.resyncs, c.reordered, c.dropped, c.max_seq) == (0, 11, 0, 111)


def test_a_second_sender_on_the_key_cannot_make_the_link_flap():
    """Two senders on one edge key, interleaved (a forger, or a process thought dead): the
    newer incarnation is followed, the older one's messages are counted and never stored.
    Following whichever came last made a link read 302 restarts and 1,587,820 dropped."""
    c = LinkCounter()
    real, forger = 1_000, 2_000  # incarnations are start times in µs
    got = []
    for k in range(300):
        got += feed(c, [(k, real), (10**6 + 7 * k, forger)])
    d = c.as_dict()
    assert got[:2] == [True, True] and not any(got[2::2])  # the real one only until the newer came
    assert d["restarts"] == 1 and d["old_incarnation"] == 299 and d["delivered"] == 301
    assert d["dropped"] == 6 * 299  # the forger's own gaps (it counts by 7): bounded by what it sent
