"""``replay --live``: publish bags over DDS at bag rate (a stand-in for ``ros2 bag play``).

The CDR bytes from the bag are published as they are (rclpy publishes serialised
messages), so no decode/encode happens; topics whose message type is not installed as
Python package are skipped with a note.
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


def play(bags: list[str], *, rate: float = 1.0, wait_s: float = 10.0, node_name: str = 'bag_player') -> int:
    """Publish ``bags`` at ``rate`` x bag speed; waits up to ``wait_s`` for a subscriber."""
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    if rate <= 0:
        raise ValueError(f'rate={rate} out of range: must be > 0')
    rclpy.init()
    node = rclpy.create_node(node_name)
    try:
        with open_bags(bags) as reader:
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            pubs = _publishers(node, reader, latched, QoSProfile(depth=100))
            if not pubs:
                raise BagError('no_usable_topic', 'no topic with an installed message type')
            end = time.monotonic() + wait_s
            while time.monotonic() < end and not any(p.get_subscription_count() for p in pubs.values()):
                rclpy.spin_once(node, timeout_sec=0.05)
            n, t0_bag, t0_wall = 0, None, time.monotonic()
            for t_ns, topic, _, data in reader.raw_messages(topics=sorted(pubs)):
                t0_bag = t_ns if t0_bag is None else t0_bag
                delay = (t_ns - t0_bag) * 1e-9 / rate - (time.monotonic() - t0_wall)
                if delay > 0:
                    time.sleep(delay)
                pubs[topic].publish(bytes(data))
                n += 1
            print(f'live: published {n} messages on {len(pubs)} topics', file=sys.stderr)
            return 2 if reader.truncated else 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
