"""bagio: scenario bags round trip through the adapters; damaged bags give BagError."""

import hashlib
import math
import shutil

import numpy as np
import pytest

from intersection_estimator import bagio
from intersection_estimator.bagio import (BAG_T0, SCENARIO_TOPICS, BagError, BagWriter, TopicInfo,
                                          detect_topics, open_bags, write_scenario_bag)
from intersection_estimator.observations import Detections
from intersection_estimator.sim import SimConfig, simulate_scenario
from msg_adapters.detections import AdapterOptions, to_detections
from msg_adapters.odometry import EgoPoseBuffer, odometry_msg, read_tf_static
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.tracked_objects import (autoware_tracked_objects_msg, derived_object_array_msg,
                                          read_objects, tracked_object_array_msg)
from msg_adapters.types import make_header

SEED = 3
MODE_OF = {SCENARIO_TOPICS['radar']: 'raw', SCENARIO_TOPICS['objects']: 'tracked',
           SCENARIO_TOPICS['autoware']: 'tracked', SCENARIO_TOPICS['detections']: 'heading'}


@pytest.fixture(scope='module')
def scenario():
    return simulate_scenario(SEED)


@pytest.fixture(scope='module')
def scenario_bag(scenario, tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'scenario'
    info = write_scenario_bag(scenario, path)
    return path, info


def read_back(path):
    """Every sensor topic through the adapters, with the mount from /tf_static."""
    ego, out, mounts = EgoPoseBuffer('map', 'base_link'), {}, {}
    with open_bags(path) as bags:
        for m in bags.messages():
            if m.topic == SCENARIO_TOPICS['tf_static']:
                mounts.update(read_tf_static(m.msg, 'base_link'))
                continue
            d = to_detections(m.msg, ego, AdapterOptions(mounts=mounts, labels=None))
            if m.topic != SCENARIO_TOPICS['odometry']:
                out.setdefault(m.topic, []).append(d)
        assert bags.problems == []
    return {t: Detections.concat(v) for t, v in out.items()}, mounts


def test_scenario_bag_round_trip(scenario, scenario_bag):
    path, info = scenario_bag
    got, mounts = read_back(path)
    assert mounts == {'radar': pytest.approx(info.mount)}
    assert info.mount == (scenario.config.sensor_mount, 0.0, 0.0) == bagio.SCENARIO_RADAR_MOUNT
    assert set(got) == set(MODE_OF)
    for topic, mode in MODE_OF.items():
        d, ref = got[topic], scenario.detections(mode)
        assert len(d) == len(ref) > 0, topic
        np.testing.assert_allclose(d.t - BAG_T0, ref.t, atol=1e-6)
        np.testing.assert_allclose(d.xy, ref.xy, atol=1e-4, err_msg=topic)   # float32 sensor frame
        if mode == 'raw':
            np.testing.assert_allclose(d.doppler, ref.doppler, rtol=1e-6, atol=1e-6)
            np.testing.assert_allclose(d.rcs, ref.rcs, rtol=1e-6, atol=1e-6)
            np.testing.assert_allclose(d.sensor_xy, ref.sensor_xy, atol=1e-6)
        else:
            np.testing.assert_allclose(np.angle(np.exp(1j * (d.heading - ref.heading))), 0, atol=1e-9)
        if mode == 'tracked':
            np.testing.assert_array_equal(d.track_id, ref.track_id)
            np.testing.assert_array_equal(d.label, ref.label)
            np.testing.assert_allclose(d.speed, ref.speed, atol=1e-9)


def test_scenario_bag_topics_frames_and_counts(scenario, scenario_bag):
    path, info = scenario_bag
    n = len(scenario.ego.t)
    with open_bags(path) as bags:
        assert bags.message_count == sum(info.counts.values())
        assert bags.time_span == pytest.approx((BAG_T0, BAG_T0 + scenario.ego.t[-1]))
    assert info.counts == {SCENARIO_TOPICS['tf_static']: 1, **{t: n for t in MODE_OF},
                           SCENARIO_TOPICS['odometry']: n}
    with open_bags(path) as bags:
        frames = {}
        for m in bags.messages():
            hdr = getattr(m.msg, 'header', None)
            if hdr is not None:
                frames.setdefault(m.topic, hdr.frame_id)
                assert m.t_ns == hdr.stamp.sec * 10**9 + hdr.stamp.nanosec
        assert frames[SCENARIO_TOPICS['radar']] == 'radar'
        assert frames[SCENARIO_TOPICS['odometry']] == 'map'
        assert {frames[t] for t in MODE_OF if t != SCENARIO_TOPICS['radar']} == {'map'}
        assert bags.detect_topics() == {          # keyed by input role (node parameter), .roles
            'odometry_topic': [SCENARIO_TOPICS['odometry']],
            'radar_topics': [SCENARIO_TOPICS['radar']],
            'detection_topics': [SCENARIO_TOPICS['detections']],
            'object_topics': [SCENARIO_TOPICS['objects']],
            'autoware_object_topics': [SCENARIO_TOPICS['autoware']]}


def test_scenario_bag_deterministic_and_small(scenario, scenario_bag, tmp_path):
    first, _ = scenario_bag
    write_scenario_bag(scenario, tmp_path / first.name)      # same name: the name is in the file

    def digest(p):
        return hashlib.sha256((p / f'{first.name}.mcap').read_bytes()).hexdigest()
    assert digest(tmp_path / first.name) == digest(first)
    info = write_scenario_bag(simulate_scenario(0, SimConfig(duration=(30.0, 30.0))), tmp_path / 'long')
    assert info.size <= 2_000_000, info.size


def test_missing_not_a_bag_and_exists(tmp_path):
    with pytest.raises(BagError) as err:
        open_bags(tmp_path / 'nope')
    assert err.value.reason == 'missing' and '\n' not in str(err.value)
    for name, data in (('x.mcap', b'not an mcap at all'), ('x.txt', b'hello'), ('e.mcap', b'')):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(BagError) as err:
            open_bags(tmp_path / name)
        assert err.value.reason == 'not_a_bag', str(err.value)
    (tmp_path / 'x.db3').write_bytes(b'garbage' * 100)
    with pytest.raises(BagError) as err:
        open_bags(tmp_path / 'x.db3')
    assert err.value.reason in ('corrupt', 'not_a_bag')
    with pytest.raises(BagError) as err:
        BagWriter(tmp_path)
    assert err.value.reason == 'exists'


@pytest.mark.parametrize('frac', [0.1, 0.55, 0.97])
def test_truncated_bag_yields_what_it_can(scenario_bag, tmp_path, frac):
    path, _ = scenario_bag
    data = (path / 'scenario.mcap').read_bytes()
    shutil.copytree(path, tmp_path / 'cut')
    (tmp_path / 'cut' / 'scenario.mcap').write_bytes(data[:int(len(data) * frac)])
    with open_bags(tmp_path / 'cut') as bags:
        assert bags.time_span[0] == pytest.approx(BAG_T0)
        msgs = list(bags.messages())
        assert [p.reason for p in bags.problems] == ['truncated']
        assert '\n' not in str(bags.problems[0])
    with open_bags(path) as bags:
        full = [(m.topic, m.t_ns) for m in bags.messages()]
    assert 0 < len(msgs) < len(full)
    assert [(m.topic, m.t_ns) for m in msgs] == full[:len(msgs)]   # a prefix, in order
    with open_bags(tmp_path / 'cut', strict=True) as bags:
        with pytest.raises(BagError) as err:
            for _ in bags.messages():
                pass
        assert err.value.reason == 'truncated'


def test_corrupt_chunk_stops_with_reason(scenario_bag, tmp_path):
    path, _ = scenario_bag
    data = bytearray((path / 'scenario.mcap').read_bytes())
    mid = len(data) // 2
    data[mid:mid + 4000] = bytes(4000)    # inside a compressed chunk
    (tmp_path / 'bad.mcap').write_bytes(bytes(data))
    with open_bags(tmp_path / 'bad.mcap') as bags:
        n = sum(1 for _ in bags.messages())
        assert [p.reason for p in bags.problems] == ['corrupt'] and n > 0


def test_no_usable_topic(tmp_path):
    with BagWriter(tmp_path / 'odom_only') as w:
        w.write('/odom', odometry_msg(w.types, 1.0, 0, 0, 0), 1.0)
    with open_bags(tmp_path / 'odom_only') as bags:
        with pytest.raises(BagError) as err:
            bags.detect_topics()
    assert err.value.reason == 'no_usable_topic' and '/odom' in str(err.value)


def test_detect_topics_by_type_and_doppler_field(tmp_path):
    with BagWriter(tmp_path / 'mixed') as w:
        T = w.types
        w.write('/front/points', radar_cloud_msg(T, make_header(T, 'radar', 1.0), [[1.0, 2.0]], [1.0]), 1.0)
        lidar = radar_cloud_msg(T, make_header(T, 'lidar', 1.0), [[1.0, 2.0]], [1.0])
        lidar.fields = lidar.fields[:3]
        w.write('/lidar/points', lidar, 1.0)
        empty = radar_cloud_msg(T, make_header(T, 'r', 1.0), np.zeros((0, 3)), [])
        w.write('/sensing/radar/empty', empty, 1.0)
        w.write('/vehicle/odom', odometry_msg(T, 1.0, 0, 0, 0), 1.0)
        w.write('/localization/kinematic_state', odometry_msg(T, 1.0, 0, 0, 0), 1.0)
    with open_bags(tmp_path / 'mixed') as bags:
        roles = bags.detect_topics()
    assert roles['radar_topics'] == ['/front/points', '/sensing/radar/empty']   # not the lidar
    assert roles['odometry_topic'] == ['/localization/kinematic_state', '/vehicle/odom']
    roles = detect_topics([TopicInfo('/sensing/radar/front', 'sensor_msgs/msg/PointCloud2', 3),
                           TopicInfo('/x', 'radar_msgs/msg/RadarScan', 1)])
    assert roles == {'radar_topics': ['/sensing/radar/front'], 'radar_scan_topics': ['/x']}


def test_three_object_families_through_a_bag(tmp_path):
    ids, xy, yaw, speed = [5, 2**31 + 7], [[1.0, 2.0], [3.0, -4.0]], [0.5, -2.0], [3.0, 7.0]
    with BagWriter(tmp_path / 'objs') as w:
        T = w.types
        h = make_header(T, 'map', 2.0)
        w.write('/ours', tracked_object_array_msg(T, h, ids, xy, yaw, speed, [1, 3]), 2.0)
        w.write('/aw', autoware_tracked_objects_msg(T, h, ids, xy, yaw, speed, [1, 3]), 2.0)
        w.write('/derived', derived_object_array_msg(T, h, ids, xy, yaw, speed, [1, 2]), 2.0)
    with open_bags(tmp_path / 'objs') as bags:
        got = {m.topic: read_objects(m.msg) for m in bags.messages()}
    families = {t: o.family for t, o in got.items()}
    assert families == {'/ours': 'ours', '/aw': 'autoware', '/derived': 'derived'}
    for topic, o in got.items():
        np.testing.assert_array_equal(o.ids, ids)
        np.testing.assert_allclose(o.xy, xy)
        np.testing.assert_allclose(o.yaw, yaw, atol=1e-12)
        np.testing.assert_allclose(o.speed, speed, atol=1e-12)


def test_embedded_schema_of_unknown_type_decodes(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg
    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg('float64 speed\nstring name\n', 'vendor_msgs/msg/Thing'))
    Thing = ts.types['vendor_msgs/msg/Thing']
    with Writer(tmp_path / 'vendor', version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection('/thing', 'vendor_msgs/msg/Thing', typestore=ts)
        w.write(c, 5, ts.serialize_cdr(Thing(speed=2.5, name='abc'), 'vendor_msgs/msg/Thing'))
    assert 'vendor_msgs/msg/Thing' not in bagio.typestore().types
    with open_bags(tmp_path / 'vendor') as bags:
        (m,) = list(bags.messages())
    assert (m.msg.speed, m.msg.name, m.t_ns) == (2.5, 'abc', 5)


def test_sqlite3_bags_and_merge_by_time(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    ts = bagio.typestore()
    from msg_adapters.types import RosbagsTypes
    R = RosbagsTypes(ts)
    with Writer(tmp_path / 'old', version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        c = w.add_connection('/odom', 'nav_msgs/msg/Odometry', typestore=ts)
        for t in (1.0, 3.0):
            w.write(c, int(t * 1e9), ts.serialize_cdr(odometry_msg(R, t, t, 0, 0), 'nav_msgs/msg/Odometry'))
    with BagWriter(tmp_path / 'new') as w:
        w.write('/pts', radar_cloud_msg(w.types, make_header(w.types, 'radar', 2.0), [[1, 1]], [0]), 2.0)
    with open_bags([tmp_path / 'old', tmp_path / 'new']) as bags:
        seq = [(m.topic, m.t) for m in bags.messages()]
    assert seq == [('/odom', 1.0), ('/pts', 2.0), ('/odom', 3.0)]


def test_typestore_has_all_families():
    ts = bagio.typestore()
    for name in ('intersection_estimator_msgs/msg/Topology', 'intersection_estimator_msgs/msg/LaneletArray',
                 'autoware_perception_msgs/msg/TrackedObjects', 'autoware_perception_msgs/msg/Shape',
                 'radar_msgs/msg/RadarScan', 'derived_object_msgs/msg/ObjectArray',
                 'unique_identifier_msgs/msg/UUID', 'visualization_msgs/msg/MarkerArray'):
        assert name in ts.types, name
    shape = [f for f, _ in ts.fielddefs['autoware_perception_msgs/msg/Shape'][1]]
    assert shape == ['type', 'footprint', 'dimensions']
    assert math.isclose(BAG_T0, 1.7e9)


def test_output_bag_latched_markers_readable_by_mcap(scenario, tmp_path):
    from mcap.reader import make_reader
    from msg_adapters.lanelets import lanelets_msg
    from msg_adapters.markers import markers_msg
    from msg_adapters.topology import read_topology, topology_msg
    with BagWriter(tmp_path / 'out') as w:
        T = w.types
        h = make_header(T, 'map', 3.0)
        w.write('/intersection_estimator/topology', topology_msg(T, h, scenario.gt, 10, -1.0, 5, 1), 3.0)
        w.write('/intersection_estimator/lanelets', lanelets_msg(T, h, scenario.gt_lanelets, 7), 3.0)
        markers, _ = markers_msg(T, h, scenario.gt, scenario.gt_lanelets)
        w.write('/intersection_estimator/markers', markers, 3.0)
    meta = (tmp_path / 'out' / 'metadata.yaml').read_text()
    assert meta.count('transient_local') == 1
    with open_bags(tmp_path / 'out') as bags:
        msgs = {m.topic: m.msg for m in bags.messages()}
    assert read_topology(msgs['/intersection_estimator/topology']).state == 'CONVERGING'
    with (tmp_path / 'out' / 'out.mcap').open('rb') as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == 3
        schemas = {s.name for s in reader.get_summary().schemas.values()}
    assert 'visualization_msgs/msg/MarkerArray' in schemas


def test_core_and_adapters_do_not_import_rclpy():
    import pathlib
    import subprocess
    import sys
    code = ('import sys, intersection_estimator.bagio, msg_adapters.detections, msg_adapters.markers, '
            'msg_adapters.topology, msg_adapters.lanelets, msg_adapters.radar_scan; '
            'intersection_estimator.bagio.typestore(); '
            'assert "rclpy" not in sys.modules, "rclpy imported"')
    subprocess.run([sys.executable, '-c', code], check=True, cwd=str(pathlib.Path(__file__).parents[1]))


def test_scenario_messages_rclpy_time_ordered(scenario):
    from msg_adapters.types import RclpyTypes
    from nav_msgs.msg import Odometry
    msgs = list(bagio.scenario_messages(scenario, RclpyTypes(), sensors=('tracked',), autoware=False))
    try:
        import tf2_msgs.msg  # noqa: F401
        keys = ('tf_static', 'odometry', 'objects')
    except ImportError:       # no tf2_msgs wheel: no /tf_static in rclpy streams
        keys = ('odometry', 'objects')
    assert msgs[0][1] == SCENARIO_TOPICS[keys[0]]
    ts = [t for t, _, _ in msgs]
    assert ts == sorted(ts)
    odo = [m for _, topic, m in msgs if topic == SCENARIO_TOPICS['odometry']]
    assert len(odo) == len(scenario.ego.t) and isinstance(odo[0], Odometry)
    assert {topic for _, topic, _ in msgs} == {SCENARIO_TOPICS[k] for k in keys}
