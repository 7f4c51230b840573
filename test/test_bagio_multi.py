"""Issue 16: several bags at once -- per-bag topics, no cross-talk, unrelated topics ignored,
split-by-topic bags in any order, the same bag twice read once (with a note)."""

from __future__ import annotations

import shutil

import pytest

from intersection_estimator.bagio import BAG_T0, BagWriter, open_bags
from intersection_estimator.replay import replay
from msg_adapters.odometry import odometry_msg

from test_replay_routes import ODOM, RADAR, cloud, params


def split_bags(root):
    """One recording split by topic: odometry in one bag, radar in another, /chatter in a third."""
    with BagWriter(root / 'odom') as w:
        for k in range(50):
            w.write(ODOM, odometry_msg(w.types, BAG_T0 + 0.1 * k, 0.0, 0.0, 0.0), BAG_T0 + 0.1 * k)
    with BagWriter(root / 'radar') as w:
        for k in range(50):
            w.write(RADAR, cloud(w.types, BAG_T0 + 0.1 * k + 0.05), BAG_T0 + 0.1 * k + 0.05)
    with BagWriter(root / 'chatter') as w:
        String = w.types.get('std_msgs/msg/String')
        for k in range(5):
            w.write('/chatter', String(data=f'hello {k}'), BAG_T0 + k)
    return root / 'odom', root / 'radar', root / 'chatter'


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    return split_bags(tmp_path_factory.mktemp('split'))


def test_a_bag_without_the_topic_yields_nothing_for_it(bags):
    odom, radar, chatter = bags
    for order in ((odom, radar, chatter), (chatter, radar, odom)):
        with open_bags(order) as b:
            got = [(m.topic, m.msgtype) for m in b.messages(topics=[RADAR])]
            assert got == [(RADAR, 'sensor_msgs/msg/PointCloud2')] * 50
            assert list(b.messages(topics=['/not/there'])) == []
            assert {m.topic for m in b.messages(topics=[ODOM, '/chatter'])} == {ODOM, '/chatter'}


@pytest.mark.parametrize('order', [(0, 1, 2), (1, 0, 2), (2, 1, 0), (2, 0, 1)])
def test_split_by_topic_bags_in_any_order_find_the_radar(bags, order):
    with open_bags([bags[i] for i in order]) as b:
        roles = b.detect_topics()
    assert roles == {'radar_topics': [RADAR], 'odometry_topic': [ODOM]}


def test_replay_of_split_bags_with_an_unrelated_topic(bags, tmp_path):
    odom, radar, chatter = bags
    for k, order in enumerate(((chatter, radar, odom), (odom, chatter, radar))):
        s = replay([str(p) for p in order], tmp_path / f'out{k}', params_file=params(tmp_path),
                   progress=False, write_outputs=False)
        assert s.received == {'radar_topics': 50, 'odometry_topic': 50}, s.received
        assert s.messages == 100


def test_the_same_bag_twice_is_read_once_and_said_so(bags, tmp_path):
    odom, radar, _ = bags
    shutil.copytree(radar, tmp_path / 'radar_copy')
    for given in ([radar, radar, odom], [radar, tmp_path / 'radar_copy', odom], [radar / 'radar.mcap', radar, odom]):
        with open_bags(given) as b:
            assert len(b.bags) == 2, given
            assert len(b.notes) == 1 and 'read once' in b.notes[0], b.notes
            assert sum(1 for m in b.messages() if m.topic == RADAR) == 50
        lines = []
        s = replay([str(p) for p in given], tmp_path / 'o', params_file=params(tmp_path), progress=False,
                   write_outputs=False, log=lines.append)
        assert s.received['radar_topics'] == 50 and any('read once' in ln for ln in lines), lines
