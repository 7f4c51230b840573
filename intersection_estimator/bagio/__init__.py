"""rosbag2 (MCAP, sqlite3) reading and writing with rosbags -- no ROS runtime, no rclpy.

Split by concern as rosbags is:

* :mod:`.typestore` -- :func:`typestore`: rosbags' Jazzy types + ``intersection_estimator_msgs``
  + the schemas of packages without a wheel (``msg_adapters/schemas``: Autoware,
  radar_msgs, derived_object_msgs); per bag, the schemas it embeds.
* :mod:`.reader` -- :func:`open_bags`: one or more bags (directories, ``.mcap`` or ``.db3``
  files) as one time-ordered stream of deserialised messages, each bag decoded with the
  schemas it embeds (types that are not installed still decode); :func:`detect_topics`:
  input topics per input role (:mod:`intersection_estimator.roles`) by message type.
* :mod:`.mcap_scan` -- a truncated or corrupt MCAP read record by record: what can be read
  is yielded, the damage recorded in :attr:`BagSet.problems` (or raised at the end with
  ``strict=True``).
* :mod:`.writer` -- :class:`BagWriter`: MCAP output bags (zstd chunks), messages built with
  ``writer.types``.
* :mod:`.scenario` -- :func:`write_scenario_bag` / :func:`scenario_messages`: a simulated
  scenario on the node's input topics; :func:`write_drive_bag`: several, one after the other.

Every failure is a :class:`BagError` whose ``reason`` is one of :data:`.errors.REASONS`
and whose ``str()`` is one line.
"""

from __future__ import annotations

from ..roles import ROLE_TYPES
from .errors import BagError
from .reader import BagMessage, BagSet, TopicInfo, detect_topics, open_bags
from .scenario import (BAG_T0, SCENARIO_FRAMES, SCENARIO_RADAR_MOUNT, SCENARIO_TOPICS, ScenarioBagInfo,
                       drive_through, scenario_messages, scenario_mount, write_drive_bag, write_scenario_bag)
from .typestore import schema_dirs, typestore
from .writer import LATCHED, BagWriter

__all__ = ['BagError', 'BagMessage', 'BagSet', 'BagWriter', 'TopicInfo', 'typestore', 'schema_dirs',
           'open_bags', 'detect_topics', 'write_scenario_bag', 'SCENARIO_TOPICS',
           'SCENARIO_FRAMES', 'SCENARIO_RADAR_MOUNT', 'BAG_T0', 'LATCHED', 'ROLE_TYPES',
           'ScenarioBagInfo', 'scenario_messages', 'scenario_mount', 'drive_through', 'write_drive_bag']
