"""The SUMO scenario family (issue 15.1): seed -> a case on a real or generated junction.

:func:`sumo_scenario` draws (all from ``numpy.random.SeedSequence(seed)``) the network
(:mod:`.sumo_net`: generated, or one of the four inD nets with ``ind_share``), the
demand (:mod:`.sumo_demand`), runs SUMO (:mod:`.sumo_run`) and returns a
:class:`~.base.FamilyScenario`:

* ground truth from the net (:mod:`.sumo_gt`; internal lanes = connectors);
* tracks = SUMO's vehicles, cyclists and pedestrians in the recorded window, plus
  parked cars at the kerb (static, outside SUMO) -- the detections come from the
  project's sensor models (:mod:`intersection_estimator.sim.sensors`: tracked, raw
  radar, heading) exactly as for the Table I simulator, with object labels by type;
* ego = SUMO vehicle ``ego`` (its pose held before it departs), the sensor on it;
* traffic per lane and the traffic-following line (:mod:`.floor`) from the *tracked
  detections* of cars and trucks, labelled with the SUMO lane each was on.

Runtime: one netconvert + one SUMO run of ``warmup_s + duration`` seconds, ~1-3 s.
"""

from __future__ import annotations

import math
from pathlib import Path
import tempfile

import numpy as np

from ..sim import SimConfig
from ..sim.sensors import scene_sensor_range
from ..sim.traffic import EgoTrajectory, Track
from .base import FamilyScenario
from .floor import drove, label_points, traffic_counts, traffic_lines
from .sumo_config import SumoConfig
from .sumo_demand import EGO_ID, sources_sinks, write_routes
from .sumo_gt import CLUSTER_M, net_gt, read_net
from .sumo_net import generate_net, ind_net
from .sumo_run import CENTER_BACK, read_fcd, run_sumo

__all__ = ['sumo_scenario', 'main_road', 'LABEL_OF']

LABEL_OF = {'car': 1, 'truck': 2, 'bike': 6, 'person': 7, 'parked': 1}
LANE_USERS = ('car', 'truck')


def _network(g, cfg: SumoConfig, folder: Path):
    if g.uniform() < cfg.ind_share:
        k = int(g.integers(1, 5))
        net, _ = ind_net(k)
        return net, None, {'net': f'inD_{k}'}
    net, plan = generate_net(g, cfg, folder)
    info = {'net': 'generated', 'arms': len(plan.arms), 'tls': plan.tls,
            'pockets': sum(a.pocket_m > 0 for a in plan.arms),
            'neighbour': any(a.neighbour_m > 0 for a in plan.arms)}
    return net, 'C', info


def _ego(tracks, n_cyc: int, rate: float, fallback_xy, fallback_yaw) -> EgoTrajectory:
    t = np.arange(n_cyc) / rate
    tr = next((x for x in tracks if x.id == EGO_ID), None)
    if tr is None or len(tr.cycle) == 0:
        xy = np.tile(fallback_xy, (n_cyc, 1))
        return EgoTrajectory(t=t, xy=xy, yaw=np.full(n_cyc, fallback_yaw), speed=np.zeros(n_cyc),
                             arm=-1, lane_index=-1)
    c = np.arange(n_cyc)
    xy = np.stack([np.interp(c, tr.cycle, tr.xy[:, 0]), np.interp(c, tr.cycle, tr.xy[:, 1])], 1)
    yaw = np.interp(c, tr.cycle, np.unwrap(tr.yaw))
    speed = np.where((c < tr.cycle[0]) | (c > tr.cycle[-1]), 0.0, np.interp(c, tr.cycle, tr.speed))
    return EgoTrajectory(t=t, xy=xy, yaw=yaw, speed=speed, arm=-1, lane_index=-1)


def _parked(g, gt, cfg: SumoConfig, n_cyc: int, rate: float, id0: int) -> list[Track]:
    """Static cars beside the kerb lanes, 15-50 m out from the stop line."""
    kerb = [ll for ll in gt.lanelets if ll.kind != 'connector' and ll.lane_index == max(
        x.lane_index for x in gt.lanelets if x.kind == ll.kind and x.arm == ll.arm)]
    n = int(g.integers(cfg.parked[0], cfg.parked[1] + 1)) if kerb else 0
    out = []
    for i in range(n):
        ll = kerb[int(g.integers(len(kerb)))]
        c = ll.center if ll.kind == 'leaving' else ll.center[::-1]
        s = float(g.uniform(15.0, 50.0))
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
        s = min(s, arc[-1])
        j = int(np.clip(np.searchsorted(arc, s), 1, len(c) - 1))
        d = ll.center[1] - ll.center[0] if len(ll.center) > 1 else np.array([1.0, 0.0])
        d = d / max(np.linalg.norm(d), 1e-9)
        p = c[j] + (3.5 / 2 + 1.2) * np.array([d[1], -d[0]])        # right of driving dir.
        yaw = math.atan2(d[1], d[0])
        t = np.arange(n_cyc) / rate
        out.append(Track(id=id0 + i, t=t, xy=np.tile(p, (n_cyc, 1)), yaw=np.full(n_cyc, yaw),
                         speed=np.zeros(n_cyc), route=('parked',)))
    return out


def main_road(gt) -> tuple[int, int]:
    """The two arms closest to opposite (with entering and leaving lanes): the main road."""
    arms = gt.intersection.arms
    ok = [i for i, a in enumerate(arms) if a.lanes_in and a.lanes_out]
    pairs = [(abs(math.remainder(arms[i].angle - arms[j].angle, 2 * math.pi)), i, j)
             for i in ok for j in ok if i < j]
    if not pairs:
        raise ValueError('no two arms with lanes both ways: no main road')
    _, i, j = max(pairs)
    return i, j


def _road_pairs(net, gt):
    """(source, sink) pairs of the through traffic on the main road (road-only cases)."""
    from .sumo_demand import through_pairs
    i, j = main_road(gt)

    def edge_of(kind, arm, end):
        ll = next(x for x in gt.lanelets if x.kind == kind and x.arm == arm)
        return net.getLane(gt.segments_of[ll.id][end]).getEdge().getID()
    return through_pairs(net, (edge_of('entering', i, 0), edge_of('entering', j, 0)),
                         (edge_of('leaving', i, -1), edge_of('leaving', j, -1)))


def _ego_choice(g, net, gt, arms=None):
    """(sumolib lane at the stop line of a random entering lanelet (of ``arms``), a sink edge)."""
    entering = sorted((ll for ll in gt.lanelets if ll.kind == 'entering'
                       and (arms is None or ll.arm in arms)), key=lambda x: x.id)
    ll = entering[int(g.integers(len(entering)))]
    lane = net.getLane(gt.segments_of[ll.id][-1])
    _, sinks = sources_sinks(net)
    return ll, lane, sinks[int(g.integers(len(sinks)))]


def _traffic(sc: FamilyScenario, fcd, gt, id_of: dict):
    """Traffic per lanelet and traffic-following lines from the tracked detections of
    cars and trucks that drove in the window (``floor.drove``), each labelled with the
    SUMO lane its vehicle was on (module doc); ``present`` per lanelet (gt.json) counts every
    vehicle seen on it, those that stood through the window too (a queue shows its approach:
    the road cases of ``evaluate``)."""
    users = [f for f in fcd if f.kind in LANE_USERS]
    dets, cyc = sc._stream('tracked')
    labels = np.full(len(dets), '', dtype=object)
    if users:
        seg = np.concatenate([f.lane for f in users])
        veh = np.concatenate([np.full(len(f.cycle), f.id) for f in users])
        lab = label_points(seg, veh, gt)
        big = 1 << 32                           # (track id, cycle) -> one sortable code
        code = np.concatenate([id_of[f.id] * big + f.cycle for f in users])
        order = np.argsort(code)
        q = dets.track_id.astype(np.int64) * big + cyc
        j = np.clip(np.searchsorted(code[order], q), 0, len(code) - 1)
        hit = code[order][j] == q
        labels[hit] = lab[order][j[hit]]
    # a vehicle seen once on a lane was there (the labels are SUMO's own lanes): a link of a
    # few metres to a neighbouring junction holds a passing vehicle for one or two rows
    present = traffic_counts(gt.lanelets, labels.astype(str), dets.track_id, min_points=1)
    labels = drove(labels.astype(str), dets.track_id, dets.xy, dets.t)
    sc.traffic = traffic_counts(gt.lanelets, labels, dets.track_id)
    sc.extra_gt = {lid: {'present': n} for lid, n in present.items()}
    for lid, line in traffic_lines(gt.lanelets, dets.xy, labels).items():
        sc.extra_gt.setdefault(lid, {})['traffic_line'] = line


def sumo_scenario(seed: int, cfg: SumoConfig = SumoConfig(), sim: SimConfig = SimConfig(),
                  workdir=None) -> FamilyScenario:
    """One SUMO case (module doc); ``workdir`` keeps the SUMO files (default: a temp dir)."""
    g_net, g_dem, g_time, g_park, g_sumo = (np.random.default_rng(s)
                                           for s in np.random.SeedSequence(seed).spawn(5))
    with tempfile.TemporaryDirectory(prefix='ie_sumo_') as tmp:
        folder = Path(workdir) if workdir is not None else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        net_path, junction, info = _network(g_net, cfg, folder)
        net = read_net(net_path)
        # a generated net's junction is its node C alone (sumo_gt module doc); inD rings cluster
        gt, _, junction = net_gt(net, junction, arm_length=cfg.gt_arm_length_m,
                                 cluster_m=CLUSTER_M if junction is None else 0.0)
        duration = float(g_time.uniform(*cfg.duration))
        end = cfg.warmup_s + duration
        only = _road_pairs(net, gt) if cfg.road_only else None
        ego_ll, ego_lane, sink = _ego_choice(g_time, net, gt, main_road(gt) if only else None)
        depart = cfg.warmup_s - 6.0 + float(g_time.uniform(0.0, 0.3)) * duration
        routes = write_routes(g_dem, net, cfg, folder, ego_lane, sink, depart, end, only)
        fcd_path = run_sumo(net_path, routes, folder, seed=int(g_sumo.integers(2 ** 31)), end=end,
                            step=cfg.step_s, record_from=cfg.warmup_s)
        # the ego's origin is its rear axle (base_link): the radar, sensor_mount ahead of it,
        # sits at the front bumper; every other vehicle is its box center (sumo_run doc)
        fcd = read_fcd(fcd_path, cfg.warmup_s, duration, cfg.step_s,
                       back={**CENTER_BACK, 'egotype': sim.sensor_mount})
    rate = 1.0 / cfg.step_s
    n_cyc = int(round(duration * rate)) + 1
    ego = _ego(fcd, n_cyc, rate, ego_ll.center[-1] - 4.0 * (ego_ll.center[-1] - ego_ll.center[-2])
               / max(np.linalg.norm(ego_ll.center[-1] - ego_ll.center[-2]), 1e-9),
               math.atan2(*(ego_ll.center[-1] - ego_ll.center[-2])[::-1]))
    others = [f for f in fcd if f.id != EGO_ID and len(f.cycle) >= 2]
    id_of = {f.id: i for i, f in enumerate(others)}
    tracks = [Track(id=i, t=f.cycle / rate, xy=f.xy, yaw=f.yaw, speed=f.speed, route=(f.kind,))
              for i, f in enumerate(others)]
    tracks += _parked(g_park, gt, cfg, n_cyc, rate, len(tracks))
    labels = {tr.id: LABEL_OF.get(tr.route[0], 1) for tr in tracks}
    sc = FamilyScenario(seed=int(seed), config=sim, gt=gt.intersection, gt_lanelets=gt.lanelets,
                        traffic={}, tracks=tracks, ego=ego, duration=duration, stop=gt.stop,
                        sensor_range=scene_sensor_range(ego, gt.lanelets, sim), labels=labels)
    _traffic(sc, others, gt, id_of)
    sc.info = {'source': 'sumo', **info, 'junction': junction, 'sumo': 'eclipse-sumo 1.28.0',
               'road_only': bool(cfg.road_only),
               'vehicles': sum(f.kind in LANE_USERS for f in others),
               'cyclists': sum(f.kind == 'bike' for f in others),
               'pedestrians': sum(f.kind == 'person' for f in others),
               'parked': len(tracks) - len(others)}
    return sc
