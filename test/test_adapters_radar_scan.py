"""radar_msgs/RadarScan: polar -> cartesian in the sensor frame."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from intersection_estimator.bagio import typestore
from msg_adapters.errors import AdapterError
from msg_adapters.radar_scan import radar_scan_msg, read_radar_scan
from msg_adapters.types import RosbagsTypes, make_header

R = [10.0, 2.0, 5.0, 4.0]
AZ = [math.pi / 2, 0.0, -math.pi / 4, math.pi]
EL = [0.0, math.pi / 6, 0.0, -math.pi / 2]
DOP = [1.5, -2.0, 0.0, 3.0]
AMP = [20.0, 5.0, -3.0, 1.0]
# hand-computed: (r cos el cos az, r cos el sin az, r sin el)
XYZ = [(0.0, 10.0, 0.0), (math.sqrt(3), 0.0, 1.0), (5 / math.sqrt(2), -5 / math.sqrt(2), 0.0),
       (0.0, 0.0, -4.0)]


def scan_through_bag_types():
    ts = typestore()
    T = RosbagsTypes(ts)
    msg = radar_scan_msg(T, make_header(T, 'radar_front', 3.5), R, AZ, EL, DOP, AMP)
    raw = ts.serialize_cdr(msg, 'radar_msgs/msg/RadarScan')
    return ts.deserialize_cdr(raw, 'radar_msgs/msg/RadarScan')


def test_known_geometry():
    res = read_radar_scan(scan_through_bag_types())
    assert res.frame_id == 'radar_front' and res.stamp == pytest.approx(3.5)
    np.testing.assert_allclose(res.xyz, XYZ, atol=1e-5)
    np.testing.assert_allclose(res.doppler, DOP, atol=1e-6)
    np.testing.assert_allclose(res.rcs, AMP, atol=1e-6)


def test_doppler_sign_and_non_finite_returns():
    msg = NS(header=NS(frame_id='/radar', stamp=NS(sec=1, nanosec=0)),
             returns=[NS(range=1.0, azimuth=0.0, elevation=0.0, doppler_velocity=2.0, amplitude=1.0),
                      NS(range=float('nan'), azimuth=0.0, elevation=0.0, doppler_velocity=2.0, amplitude=1.0),
                      NS(range=1.0, azimuth=0.0, elevation=0.0, doppler_velocity=float('inf'),
                         amplitude=1.0)])
    res = read_radar_scan(msg, doppler_sign=-1)
    assert res.frame_id == 'radar' and len(res) == 1 and res.dropped == 2
    assert res.doppler[0] == -2.0


def test_empty_and_malformed():
    empty = NS(header=NS(frame_id='radar', stamp=NS(sec=1, nanosec=0)), returns=[])
    assert len(read_radar_scan(empty)) == 0
    bad = NS(header=empty.header, returns=[NS(range='far')])
    with pytest.raises(AdapterError) as err:
        read_radar_scan(bad)
    assert err.value.reason == 'malformed'
