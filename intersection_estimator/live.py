"""``replay --live``: publish bags over DDS at bag rate (a stand-in for ``ros2 bag play --clock``).

The CDR bytes from the bag are published as they are (rclpy publishes serialised
messages), so no decode/encode happens; topics whose message type is not installed as
Python package are skipped with a note. ``/clock`` (rosgraph_msgs/Clock) carries the bag
time, at every message and at ``clock_hz`` in between, so that a node started with
``use_sim_time:=true`` ticks in bag time (its timer follows /clock).
"""

from __future__ import annotations

import sys
import time

from .bagio import BagError, open_bags

__all__ = ['play']


def _publishers(node, reader, latched_qos, default_qos):
    from msg_adapters.types import RclpyTypes
    types, pubs = RclpyTypes(), {}
    for info in reader.topics:
        try:
            cls = types.get(info.msgtype).msgclass
        except (ImportError, AttributeError):
            print(f'live: skipping {info.topic}: {info.msgtype} is not installed', file=sys.stderr)
            continue
        qos = latched_qos if info.topic.endswith(('markers', 'tf_static')) else default_qos
        pubs[info.topic] = node.create_publisher(cls, info.topic, qos)
    return pubs


def play(bags: list[str], *, rate: float = 1.0, wait_s: float = 10.0, node_name: str = 'bag_player',
         clock_hz: float = 40.0) -> int:
    """Publish ``bags`` at ``rate`` x bag speed, and ``/clock``; waits up to ``wait_s`` for
    subscribers (:func:`settled`)."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    if rate <= 0:
        raise ValueError(f'rate={rate} out of range: must be > 0')
    if clock_hz <= 0:
        raise ValueError(f'clock_hz={clock_hz} out of range: must be > 0')
    if not wait_s >= 0:
        raise ValueError(f'wait={wait_s} out of range: must be >= 0 [s]')
    rclpy.init()
    node = rclpy.create_node(node_name)
    try:
        with open_bags(bags) as reader:
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            pubs = _publishers(node, reader, latched, QoSProfile(depth=100))
            if not pubs:
                raise BagError('no_usable_topic', 'no topic with an installed message type')
            pubs.pop('/clock', None)   # a recorded /clock is replaced by ours
            clock = _Clock(node, rate, clock_hz)
            topics = ['/clock', *pubs]
            matched = settled([clock.pub, *pubs.values()], wait_s,
                              lambda: rclpy.spin_once(node, timeout_sec=0.05))
            if not matched:
                print(f'live: no subscriber after {wait_s:g} s; publishing anyway', file=sys.stderr)
            else:
                print(f"live: subscribed: {', '.join(topics[i] for i in sorted(matched))}", file=sys.stderr)
            n = 0
            for t_ns, topic, _, data in reader.raw_messages(topics=sorted(pubs)):
                clock.until(t_ns)
                pubs[topic].publish(bytes(data))
                n += 1
            from rclpy.duration import Duration
            for p in (clock.pub, *pubs.values()):     # delivered before the node goes (reliable QoS)
                p.wait_for_all_acked(Duration(seconds=2.0))
            print(f'live: published {n} messages on {len(pubs)} topics and /clock', file=sys.stderr)
            return 2 if reader.truncated else 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


#: the matched publishers must stay the same this long before the bag starts [s]
SETTLE_S = 1.0


def settled(pubs, wait_s: float, spin, settle_s: float = SETTLE_S, clock=time.monotonic) -> set:
    """Indices of ``pubs`` with a matched subscriber, once that set is non-empty and has not
    changed for ``settle_s``, or whatever it is after ``wait_s``. Discovery matches topic by
    topic: a bag started at the first match loses the first messages of a topic matched later
    (docs/replay.md, ``--live``). ``spin`` runs the graph one step."""
    end = clock() + wait_s
    matched, since = set(), clock()
    while clock() < end:
        now = {i for i, p in enumerate(pubs) if p.get_subscription_count()}
        if now != matched:
            matched, since = now, clock()
        elif matched and clock() - since >= settle_s:
            break
        spin()
    return matched


class _Clock:
    """``/clock`` at bag time: sleeps until a bag time is due (at ``rate``), publishing the
    interpolated bag time every ``1 / clock_hz`` wall seconds meanwhile (as ``ros2 bag play
    --clock`` does), then that time itself."""

    def __init__(self, node, rate: float, clock_hz: float):
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        self._msg = Clock
        self.pub = node.create_publisher(Clock, '/clock', QoSProfile(depth=10))
        self.rate, self.step = rate, 1.0 / clock_hz
        self.t0_bag = self.t0_wall = None

    def publish(self, t_ns: int) -> None:
        msg = self._msg()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 10**9)
        self.pub.publish(msg)

    def until(self, t_ns: int) -> None:
        if self.t0_bag is None:
            self.t0_bag, self.t0_wall = t_ns, time.monotonic()
        due = self.t0_wall + (t_ns - self.t0_bag) * 1e-9 / self.rate
        while (left := due - time.monotonic()) > 0:
            time.sleep(min(left, self.step))
            now = min(time.monotonic(), due)
            self.publish(self.t0_bag + int((now - self.t0_wall) * self.rate * 1e9))
        self.publish(t_ns)
