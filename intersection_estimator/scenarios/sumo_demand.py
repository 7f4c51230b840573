"""Demand of a SUMO case (issue 15.1): routes driven by demand, so that some lanes carry
no traffic.

Every source edge (an edge entering the network) -> sink edge relation gets a flow of
``route_vph`` vehicles per hour, or none with probability ``zero_route_prob``; SUMO's
strategic lane choice then leaves lanes whose turns nobody takes (a right-turn pocket
without right-turners) empty. The vehicle mix has cars, trucks and cyclists (on the
road lanes); pedestrians walk on the sidewalks and cross at the crossings (nets with
sidewalks only). The ego vehicle (id ``ego``) departs on one entering lane of the
junction under test and stops a few metres before its stop line (holding the queue
behind it), as the ego of the Table I simulator does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .sumo_config import SumoConfig

__all__ = ['sources_sinks', 'write_routes', 'through_pairs', 'EGO_ID', 'VTYPE_LENGTH']

#: Length [m] of each vehicle type the routes use (SUMO's defaults for passenger cars and
#: bicycles, written out so that ``read_fcd`` finds the box center with the same number).
VTYPE_LENGTH = {'car': 5.0, 'truck': 10.0, 'bike': 1.6, 'egotype': 5.0}

EGO_ID = 'ego'


def _is_vehicle_edge(e) -> bool:
    return e.getFunction() in ('', 'normal') and any(ln.allows('passenger') for ln in e.getLanes())


def sources_sinks(net) -> tuple[list[str], list[str]]:
    """Edges entering the network (no connection leads into them) and edges leaving it
    (no connection leads out; turnarounds are off in generated nets)."""
    src, snk = [], []
    for e in net.getEdges(withInternal=False):
        if not _is_vehicle_edge(e):
            continue
        a, b = e.getFromNode(), e.getToNode()
        ins = [x for x in e.getIncoming() if _is_vehicle_edge(x) and x.getFromNode() != b]
        outs = [x for x in e.getOutgoing() if _is_vehicle_edge(x) and x.getToNode() != a]
        if not ins:
            src.append(e.getID())
        if not outs:
            snk.append(e.getID())
    return sorted(src), sorted(snk)


def _vtypes(cfg: SumoConfig) -> str:
    car = 1.0 - cfg.bicycle_share - cfg.truck_share
    L = {k: f'{v:g}' for k, v in VTYPE_LENGTH.items()}
    return ('  <vTypeDistribution id="mix">\n'
            f'    <vType id="car" vClass="passenger" length="{L["car"]}" probability="{car:.3f}"/>\n'
            f'    <vType id="truck" vClass="truck" length="{L["truck"]}" probability="{cfg.truck_share:.3f}"/>\n'
            f'    <vType id="bike" vClass="bicycle" length="{L["bike"]}" probability="{cfg.bicycle_share:.3f}"/>\n'
            '  </vTypeDistribution>\n'
            f'  <vType id="egotype" vClass="passenger" length="{L["egotype"]}"/>\n')


def _flows(rng, net, cfg: SumoConfig, end: float, only=None) -> list[str]:
    """Flows of every source -> sink relation (``only``: just these (source, sink) pairs,
    none left empty)."""
    src, snk = sources_sinks(net)
    out = []
    for s in src:
        a = net.getEdge(s).getFromNode()
        for t in snk:
            if only is not None:
                if (s, t) not in only:
                    continue
            elif net.getEdge(t).getToNode() == a or rng.uniform() < cfg.zero_route_prob:
                continue
            vph = float(rng.uniform(*cfg.route_vph))
            out.append(f'  <flow id="f_{s}_{t}" type="mix" from="{s}" to="{t}" begin="0" '
                       f'end="{end:.1f}" vehsPerHour="{vph:.1f}" departLane="best" '
                       'departSpeed="max"/>')
    return out


def _persons(rng, net, cfg: SumoConfig, end: float) -> list[str]:
    walk = [e.getID() for e in net.getEdges(withInternal=False)
            if e.getFunction() in ('', 'normal') and any(ln.getPermissions() == {'pedestrian'}
                                                         for ln in e.getLanes())]
    rate = float(rng.uniform(*cfg.pedestrians_per_h))
    if len(walk) < 2 or rate <= 0:
        return []
    out = []
    for i in range(4):
        a, b = rng.choice(len(walk), size=2, replace=False)
        out.append(f'  <personFlow id="p{i}" begin="0" end="{end:.1f}" '
                   f'personsPerHour="{rate / 4:.1f}"><walk from="{walk[a]}" to="{walk[b]}"/>'
                   '</personFlow>')
    return out


def _ego(lane, sink: str, depart: float, stop_gap: float) -> str:
    edge = lane.getEdge()
    end_pos = max(lane.getLength() - stop_gap, 1.0)
    return (f'  <trip id="{EGO_ID}" type="egotype" depart="{depart:.1f}" from="{edge.getID()}" '
            f'to="{sink}" departLane="{lane.getIndex()}" departPos="0" departSpeed="max">\n'
            f'    <stop lane="{lane.getID()}" endPos="{end_pos:.2f}" duration="100000"/>\n'
            '  </trip>')


def through_pairs(net, in_edges: tuple, out_edges: tuple) -> set:
    """(source, sink) pairs of the through traffic between two arms: for arm entering edge
    ``in_edges[i]`` the source nearest upstream, for leaving edge ``out_edges[1 - i]`` the
    sink nearest downstream."""
    src, snk = sources_sinks(net)

    def nearest(cands, a, b_of):
        best = []
        for c in cands:
            path, cost = net.getShortestPath(*b_of(c, a))
            if path is not None:
                best.append((cost, c))
        return min(best)[1] if best else None
    pairs = set()
    for i in (0, 1):
        s = nearest(src, net.getEdge(in_edges[i]), lambda c, a: (net.getEdge(c), a))
        t = nearest(snk, net.getEdge(out_edges[1 - i]), lambda c, a: (a, net.getEdge(c)))
        if s is not None and t is not None:
            pairs.add((s, t))
    return pairs


def write_routes(rng, net, cfg: SumoConfig, folder, ego_lane, ego_sink: str, depart: float,
                 end: float, only=None) -> Path:
    """``routes.rou.xml``: vehicle types, flows, pedestrians and the ego trip (sorted by
    departure, as SUMO wants). ``only``: (source, sink) pairs -- a road case (all traffic
    on one axis, no pedestrians)."""
    body = _flows(rng, net, cfg, end, only) + ([] if only is not None else
                                               _persons(rng, net, cfg, end))
    ego = _ego(ego_lane, ego_sink, depart, float(rng.uniform(2.0, 6.0)))
    path = Path(folder) / 'routes.rou.xml'
    path.write_text('<routes>\n' + _vtypes(cfg) + '\n'.join(body + [ego]) + '\n</routes>\n')
    return path
