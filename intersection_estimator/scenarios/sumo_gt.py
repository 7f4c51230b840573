"""Ground truth from a SUMO network (issue 15.1): lanes from the net, internal lanes =
connectors, read with ``sumolib.net.readNet(path, withInternal=True)``.

Every lane a passenger car may use becomes a lane-graph
:class:`~.lanegraph.Segment` (its shape, width, successors through the connections'
internal ``via`` lanes). Internal lanes of a *real* junction (a node joined to three or
more other nodes) are connector segments -- those of the junction under test form the
box, those of a neighbouring junction end the arms there; internal lanes of a node
with two neighbours (a turn pocket's split node, a shape node) are plain lane pieces.
Real junctions joined by an edge shorter than ``cluster_m`` (default :data:`CLUSTER_M`)
are one junction (the inD nets draw some intersections as a ring of nodes): their
internal lanes and the lanes of the short edges between them are all connector segments
of that cluster. A generated net knows its junction under test (node ``C``) and passes
``cluster_m=0``: its neighbouring junction ``N<arm>`` is a junction of its own even when
the two boxes leave less than 25 m of road between them (issue 15: no arm from a
neighbouring junction's traffic).
Then :func:`~.lanegraph.gt_from_lane_graph` builds the intersection and lanelets.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..components import components
from .lanegraph import LaneGraphGT, Segment, gt_from_lane_graph

__all__ = ['read_net', 'net_segments', 'junction_of', 'main_junction', 'net_gt', 'CLUSTER_M', 'snap_connectors']

CLUSTER_M = 25.0


def read_net(path):
    import sumolib
    return sumolib.net.readNet(str(path), withInternal=True)


def junction_of(internal_lane_id: str) -> str:
    """':C_3_0' -> 'C' (internal edge ids are ':<junction>_<index>')."""
    return internal_lane_id[1:].rsplit('_', 2)[0]


def _clusters(net, cluster_m: float = CLUSTER_M) -> dict:
    """{node id: cluster id} of the real junctions (module doc)."""
    real = set()
    for node in net.getNodes():
        nbrs = {e.getToNode().getID() for e in node.getOutgoing()} | {
            e.getFromNode().getID() for e in node.getIncoming()}
        nbrs.discard(node.getID())
        if len(nbrs) >= 3:
            real.add(node.getID())
    pairs = []
    for e in net.getEdges(withInternal=False):
        a, b = e.getFromNode().getID(), e.getToNode().getID()
        if a in real and b in real and a != b and e.getLength() < cluster_m:
            pairs.append((a, b))          # node positions of hand-drawn nets mislead: by edge
    return {n: g[0] for g in components(sorted(real), pairs) for n in g}


def _succ_ids(lane) -> list[str]:
    out = []
    for c in lane.getOutgoing():
        if not c.getToLane().allows('passenger'):
            continue
        out.append(c.getViaLaneID() or c.getToLane().getID())
    return out


def net_segments(net, cluster_m: float = CLUSTER_M) -> tuple[dict, dict]:
    """({lane id: Segment} of every lane passenger cars may use, {connector lane id:
    junction cluster id}) (module doc)."""
    cluster = _clusters(net, cluster_m)
    segs, box_of = {}, {}
    for edge in net.getEdges(withInternal=True):
        fn = edge.getFunction()
        if fn not in ('', 'normal', 'internal'):
            continue
        if fn == 'internal':
            jc = cluster.get(junction_of(edge.getID() + '_0'))
        else:
            a, b = (cluster.get(edge.getFromNode().getID()), cluster.get(edge.getToNode().getID()))
            jc = a if a is not None and a == b else None
        for lane in edge.getLanes():
            if not lane.allows('passenger'):
                continue
            lid = lane.getID()
            shape = np.array([p[:2] for p in lane.getShape()], float)
            segs[lid] = Segment(id=lid, center=shape, width=float(lane.getWidth()),
                                succs=_succ_ids(lane), connector=jc is not None)
            if jc is not None:
                box_of[lid] = jc
    for s in segs.values():
        s.succs = [x for x in s.succs if x in segs]
    for s in segs.values():
        for x in s.succs:
            segs[x].preds.append(s.id)
    return segs, box_of


def main_junction(box_of: dict) -> str:
    """The junction cluster with the most connector segments (the one under test)."""
    count: dict = {}
    for j in box_of.values():
        count[j] = count.get(j, 0) + 1
    if not count:
        raise ValueError('net has no junction with three or more neighbours')
    return max(sorted(count), key=count.get)


def net_gt(path_or_net, junction: str | None = None, *, arm_length: float = 60.0,
           cluster_m: float = CLUSTER_M) -> tuple[LaneGraphGT, dict, str]:
    """(ground truth, segments, junction cluster id) of a net's junction (default: the
    main one; a node id names its cluster; ``cluster_m``: module doc)."""
    net = read_net(path_or_net) if isinstance(path_or_net, (str, Path)) else path_or_net
    segs, box_of = net_segments(net, cluster_m)
    junction = (main_junction(box_of) if junction is None
                else _clusters(net, cluster_m).get(junction, junction))
    box = [k for k, j in box_of.items() if j == junction]
    return gt_from_lane_graph(segs, box, arm_length=arm_length), segs, junction


def snap_connectors(lls) -> None:
    """SUMO's ground truth as a Lanelet2 map: SUMO's internal lanes (our connectors) start
    and end 0.1-0.4 m from the lanes they join, so lanelet2's routing graph (shared end
    points) would see no connection and the map no intersection. A map's lanelets share
    their end points; move each connector's ends onto its entering / leaving lane (only
    the virtual connector pieces change, never an entering or leaving lane)."""
    by = {l.id: l for l in lls}
    for l in lls:
        if l.kind == 'connector':
            continue
        for sid in l.successors:                       # entering lane -> connector
            c = by.get(sid)
            if c is not None and c.kind == 'connector':
                c.left[0], c.right[0] = l.left[-1], l.right[-1]
                c.center[0] = 0.5 * (c.left[0] + c.right[0])
    for c in lls:
        if c.kind != 'connector':
            continue
        for sid in c.successors:                       # connector -> leaving lane
            o = by.get(sid)
            if o is not None and o.kind != 'connector':
                c.left[-1], c.right[-1] = o.left[0], o.right[0]
                c.center[-1] = 0.5 * (c.left[-1] + c.right[-1])
