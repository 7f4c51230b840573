"""``live.settled``: the player starts the bag once discovery has matched its subscribers
(no DDS here: publishers and the clock are stand-ins)."""

from __future__ import annotations

import pytest

from intersection_estimator.live import play, settled


class _Pub:
    """A publisher whose subscriber is matched from time ``at`` on (None: never)."""

    def __init__(self, clock, at):
        self.clock, self.at = clock, at

    def get_subscription_count(self):
        return int(self.at is not None and self.clock() >= self.at)


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t

    def spin(self):
        self.t += 0.05


def test_the_bag_waits_for_the_topics_that_match_later():
    """/clock matches at 0.3 s, the data topic at 0.9 s, a recorded topic nobody reads never:
    the bag starts once both have matched and nothing changed for the settle time, not at
    the first match (the data topic's first messages would be lost)."""
    c = _Clock()
    pubs = [_Pub(c, 0.3), _Pub(c, 0.9), _Pub(c, None)]
    assert settled(pubs, 10.0, c.spin, settle_s=1.0, clock=c) == {0, 1}
    assert 1.9 <= c.t < 2.1
    # nobody listening: the whole wait, then nothing
    c2 = _Clock()
    assert settled([_Pub(c2, None)], 3.0, c2.spin, settle_s=1.0, clock=c2) == set()
    assert c2.t >= 3.0
    # matched late in the wait: what matched by then
    c3 = _Clock()
    assert settled([_Pub(c3, 2.9)], 3.0, c3.spin, settle_s=1.0, clock=c3) == {0}


def test_a_negative_wait_is_refused_by_name():
    with pytest.raises(ValueError, match='wait'):
        play(['nowhere'], wait_s=-1.0)
