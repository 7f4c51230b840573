"""What one drive's estimate shows against one mapped intersection (issue 17, "Changes").

Change kinds say how the *world* differs from the map:

========================  =====================================================================
``arm_added``             an estimated arm no mapped arm matches (by angle, :mod:`.match`)
``arm_removed``           a mapped arm no estimated arm matches although enough vehicles were
                          seen turning between the other arms to show it (absence, below,
                          :func:`_arm_absence`); else the arm is only *unobserved* and nothing
                          is claimed
``lane_added/_removed``   a matched arm has more / fewer lanes in one direction than mapped
                          (removed: an absence, below)
``lane_moved``            same lane count, but a lane's estimated center line lies more than
                          ``moved_m`` (0.75 m) from the mapped one on average
``connector_added``       a turn driven (an estimated connector, paper §III: connectors are
                          created only from trajectories) that the map lacks
``connector_unused``      a mapped connector no vehicle took although enough passages went
                          through its entering lane (an absence; "unused", not "removed")
========================  =====================================================================

Lanes are identified by position: an estimated lane is the mapped lane it lies on (mutual
nearest center lines, :func:`_lane_identity`), not the mapped lane with its index; lane
moved, the turns' keys and the lanes a drive drove use that identity.

Evidence is the vehicle passages each estimated arm explains: the topology estimator
reports an arm's confidence as ``1 - exp(-passages / 3)`` (:mod:`intersection_estimator.topology`),
so ``passages = -3 ln(1 - confidence)``. A positive finding's log likelihood ratio is
``logit(confidence)`` of the arm(s) it rests on, for lane-level findings (lane moved / added,
turn added) at most ``vehicles / 3`` of the vehicles that drove the estimated lane or turn
(1/3 nat per vehicle, the unit of that rule), against the prior odds ``logit(change_prior)``
(default 0.5: prior odds 1). A finding is claimed when its posterior is above 0.5.

*Absences* (arm removed, lane removed, connector unused) rest on traffic that did not
happen: if the element still existed and took a share ``f`` of the ``P`` passages that could
have used it, all of them missing it has probability ``(1 - f)^P``, so the log likelihood
ratio "gone : still there" is ``-P ln(1 - f)``, added to the prior log odds
``logit(absence_prior)`` (default 0.2: a mapped element is more likely there than not).
With ``share_concentration`` k > 0 the share itself varies between elements
(``Beta(k f, k (1 - f))``) and the likelihood is ``B(a, b + P) / B(a, b)`` (:func:`_absence`).
A missing lane is one finding per mapped lane (key = its id); a drive whose vehicles drove
that lane refutes it (``DriveView.lanes_seen``), and a drive that matched a mapped arm
refutes its removal, whatever the arm's confidence (:meth:`DriveView.contradiction`).
With ``turn_absence`` the passages are the vehicles that could have used the element: for a
lane those of the turns the map gives it (:func:`_lane_absence`), for an arm those seen
turning between the other arms (:func:`_arm_absence`). With ``share_from_traffic`` a lane's
share of its turns is not taken as exactly ``1 / n``: how evenly the drive's vehicles spread
over the lanes of a turn, and how often one is seen on a lane the map does not give its turn,
are read from the drive's other arm directions (:func:`lane_choice`).
A mapped connector is only judged when the drive's vehicles left its entering lane through
another connector to a matched arm; its passages are the turns seen from that lane (a
lower bound: one vehicle each). A drive claims an absence
only when that posterior exceeds 0.5; below, the finding is kept as ``weak`` so that
several drives' evidence can add up (:mod:`.fuse`), and a mapped arm without traffic is
listed as *unobserved*.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.special import gammaln, hyp2f1
from scipy.stats import beta as beta_dist

from ..evaluate import _cost_matrix, lane_distance, resample
from ..model import ENTERING, LEAVING
from ..ranges import check_table
from .corroborate import FOLLOW_SHARE, refutes
from .match import ARM_GATE_DEG, GATE_M, match_arms

__all__ = ['KINDS', 'ChangeConfig', 'Finding', 'DriveView', 'compare', 'arm_passages']

KINDS = ('arm_added', 'arm_removed', 'lane_added', 'lane_removed', 'lane_moved',
         'connector_added', 'connector_unused')
DIRS = {ENTERING: 'in', LEAVING: 'out'}


_RANGES = {'gate_m': ('(0, inf)', 'estimate <-> mapped intersection gate [m]'),
           'arm_gate_deg': ('(0, 180]', 'arm <-> mapped arm gate [deg]'),
           'moved_m': ('(0, inf)', 'lane moved beyond this mean offset [m]'),
           'absence_prior': ('(0, 1)', 'prior probability that an element without traffic is gone'),
           'min_confidence': ('(0, 1)', 'fused confidence to report a change'),
           'change_prior': ('(0, 1)', 'prior probability of a positive change (added / moved)'),
           'share_concentration': ('[0, inf)', 'spread of traffic shares in the absence model (0: off)'),
           'share_from_traffic': ('[0, 1]', "1: a missing lane's share spread is read from the drive's "
                                  'lane choices on the map (tracked input)'),
           'turn_absence': ('[0, 1]', "1: a missing lane's evidence is the vehicles of the turns it serves"),
           'corroborate': ('[0, 1]', "1: claims the drive's map-matched vehicles contradict are dropped"),
           'match_gate_m': ('(0, inf)', 'a vehicle is on a mapped lane within this lateral distance [m]'),
           'match_min_points': ('[1, inf)', 'positions (1 s averages) that make a vehicle a lane\'s traffic'),
           'turn_follow': ('[0, 1]', 'a vehicle that followed a mapped turn past this share of it took '
                           'it, whatever lane beside it left on (0: off)'),
           'empty_calibration': ('[0, 1]', "1: a missing lane's evidence is scaled by how often the "
                                 "drive's other mapped lanes stood empty against the lane-choice model"),
           'empty_prior': ('(0, inf)', 'pseudo lanes that stood empty as the model expects, in that check')}


@dataclass(frozen=True)
class ChangeConfig:
    gate_m: float = GATE_M                 # estimate <-> mapped intersection [m]
    arm_gate_deg: float = ARM_GATE_DEG     # arm <-> mapped arm [deg]
    moved_m: float = 0.75                  # lane moved beyond this mean offset [m]
    absence_prior: float = 0.2             # prior probability that an element without traffic is gone
    min_confidence: float = 0.5            # fused confidence to report a change
    # prior probability of a positive change (arm/lane/turn added, lane moved); 0.5 = prior odds
    # 1: a lane-level change shown by one vehicle (1/3 nat) is claimed by one drive (the Table I
    # single-drive figures need it: the changed lane or turn often has 1-2 vehicles)
    change_prior: float = 0.5
    # how much traffic shares vary between elements (Dirichlet concentration of the shares of
    # an absence; 0 = every element takes exactly its share, (1 - f)^P). Measured on the
    # ground-truth traffic: SUMO lanes 3.4 (24 % of the lanes of a used direction undriven),
    # SUMO arms 62, Table I under-dispersed. Default 0 (see docs/fleet.md: 3 costs Table I's
    # lane_removed recall 98 -> 55 %)
    share_concentration: float = 0.0
    # the spread of a lane's share of its turns is read from the drive itself: how evenly its
    # vehicles chose among the mapped lanes serving the same turn on the *other* arm directions
    # (lane_concentration; needs the map-matched traffic, else share_concentration)
    share_from_traffic: int = 1
    # a mapped lane serves its mapped turns: only vehicles of those turns can show it missing
    # (_lane_absence; 0 = any vehicle of the direction, the rule before)
    turn_absence: int = 1
    # the drive's vehicles map-matched to the mapped lanes drop the claims they contradict
    # (corroborate.py); needs tracked input (raw radar: nothing to match)
    corroborate: int = 1
    match_gate_m: float = 1.75
    match_min_points: int = 5
    # a lane change right after the box is no turn the map lacks (corroborate.FOLLOW_SHARE)
    turn_follow: float = FOLLOW_SHARE
    # the lane-choice model's probability that a lane stands empty, checked against the drive's
    # other mapped lanes (lane_choice, empty_ratio; docs/fleet.md)
    empty_calibration: int = 1
    empty_prior: float = 1.0

    def validate(self) -> None:
        check_table(self, _RANGES, 'ChangeConfig')


@dataclass
class Finding:
    """One change one drive shows; ``key`` identifies it across drives."""

    kind: str
    key: str
    confidence: float
    map_arm: int = -1
    direction: str = ''
    map_lanes: list = field(default_factory=list)
    evidence: dict = field(default_factory=dict)
    log_lr: float = float('nan')     # log likelihood ratio of this drive (nan: logit(confidence))
    prior: float = 0.0               # prior log odds of the kind (absences: logit(absence_prior))

    def __post_init__(self):
        if math.isnan(self.log_lr):
            self.log_lr = _logit(self.confidence)


@dataclass
class DriveView:
    """One drive against one mapped intersection: findings and what the drive saw."""

    intersection: str
    findings: list[Finding]
    arm_conf: dict[int, float]      # mapped arm -> confidence of the estimated arm matched to it
    counts_ok: set                  # (mapped arm, 'in'|'out') with the mapped lane count
    used: set                       # mapped connector ids the drive's traffic took
    total_conf: float               # confidence that the drive saw the intersection at all
    passages: float
    unobserved: list[int]           # mapped arms without traffic (nothing claimed)
    weak: list = field(default_factory=list)   # findings below 0.5 in this drive (for fusion)
    lanes_seen: set = field(default_factory=set)   # mapped lane ids an estimated lane with traffic lay on
    lane_conf: dict = field(default_factory=dict)  # mapped lane id -> how well the drive saw it (logit = vehicles / 3)
    # log LR "no such arm" of this drive's passages, none of which used an arm the map lacks
    # (an absence, as arm_removed); None: the old rule, total_conf
    no_new_arm_llr: float | None = None

    def contradiction(self, f: Finding) -> float:
        """How strongly this drive (not showing ``f``) speaks against ``f`` (0 = it cannot).

        Against an absence (arm/lane removed, connector unused), a drive whose vehicles used
        the element is direct evidence that it is there: ``P_MAX``.
        """
        if f.kind == 'arm_added':
            # a drive without the arm: its passages all missed it (absence evidence, not certainty)
            if self.no_new_arm_llr is None:
                return self.total_conf
            return 1.0 / (1.0 + math.exp(-min(self.no_new_arm_llr, 50.0)))
        ok = (f.map_arm, f.direction) in self.counts_ok       # the drive saw the mapped lanes
        seen = self.arm_conf.get(f.map_arm, 0.0)
        # Traffic on an element refutes its absence whatever the arm's confidence: the
        # confidence 1 - exp(-passages / 3) says how much traffic the arm explains, not
        # whether that traffic is real. Measured on short drives (Table I cases 2000-2019,
        # 10 drives of 30 %): no estimated arm without a world arm (0 of 847), a lane the
        # world lacks "driven" in 1 of 194 drives (0 of 24 on arms <= 0.5), real lanes
        # driven in 57 % of the drives on arms <= 0.5 (72 % above). The old gate (arm > 0.5)
        # let the drives that saw a quiet arm or lane count nothing while every drive that
        # missed it added its absence evidence (docs/fleet.md, rule 7).
        if f.kind == 'arm_removed':
            return P_MAX if f.map_arm in self.arm_conf else 0.0
        if f.kind == 'lane_removed':
            # the drive's vehicles drove the mapped lane(s) the finding says are gone
            there = bool(f.map_lanes) and all(l in self.lanes_seen for l in f.map_lanes)
            return P_MAX if there or (ok and seen > 0.5) else 0.0
        if f.kind == 'lane_moved':         # as well as this drive saw that lane (its vehicles)
            return min(seen, self.lane_conf.get(f.map_lanes[0], seen)) if ok and f.map_lanes else 0.0
        if f.kind == 'lane_added':         # only a drive with the mapped count
            return seen if ok else 0.0
        if f.kind == 'connector_unused':
            return P_MAX if f.map_lanes[0] in self.used else 0.0
        return 0.0          # connector_added: a turn nobody took in this drive still exists


def arm_passages(confidence: float) -> float:
    """Vehicle passages behind an arm's confidence ``1 - exp(-p / 3)`` (topology.best)."""
    return -3.0 * math.log1p(-min(float(confidence), 1.0 - 1e-12))


P_MAX = 0.999        # no single drive is certain


def _logit(p: float) -> float:
    p = min(max(p, 0.5), P_MAX)
    return math.log(p / (1.0 - p))


def _positive(kind, key, p, cfg, vehicles=None, **kw) -> Finding:
    """A positive finding. Its log likelihood ratio is ``logit(p)`` of the arm's posterior
    confidence ``p``, and, when the change rests on particular vehicles (lane-level findings:
    the vehicles that drove the estimated lane or turn), at most ``vehicles / 3``: every
    vehicle passage is worth 1/3 nat, the unit of the confidence rule ``1 - exp(-n / 3)`` of
    arms and lanes (``logit`` of it tends to ``n / 3``). Against the prior odds
    ``logit(change_prior)``. Per-vehicle evidence adds up over drives (fusion)."""
    prior = math.log(cfg.change_prior / (1.0 - cfg.change_prior))
    llr = _logit(p) if p > 0.5 else 0.0
    if vehicles is not None:
        llr = min(llr, float(vehicles) / 3.0)
    conf = 1.0 / (1.0 + math.exp(-min(max(llr + prior, -50.0), 50.0)))
    return Finding(kind, key, conf, log_lr=llr, prior=prior, **kw)


def _lane_conf(lanes) -> float:
    """Confidence of estimated lanes from the vehicles that drove them: ``1 - exp(-support / 3)``
    (the lane estimator's and the topology arms' rule)."""
    return 1.0 - math.exp(-sum(l.support for l in lanes) / 3.0)


def _absence_llr(passages: float, share: float, cfg, k: float | None = None, off: float = 0.0) -> float:
    """Log LR "gone : still there" of ``passages`` that all missed an element taking ``share``
    of them (:func:`_absence`; ``k``: the share's concentration, default the config's).
    ``off``: the probability that a passage on the element is seen elsewhere (a late lane
    change, a matching slip), so each misses it with ``1 - (1 - off) f``:
    ``-ln E[(1 - (1 - off) f)^P] = -ln 2F1(-P, k share; k; 1 - off)``."""
    share = min(max(share, 1e-9), 1.0 - 1e-9)
    k = cfg.share_concentration if k is None else k
    if passages <= 0.0:
        return 0.0
    if k > 0 and off > 0:
        return -math.log(max(float(hyp2f1(-passages, share * k, k, 1.0 - off)), 1e-300))
    if k > 0:
        a, b = share * k, (1.0 - share) * k
        return -(math.lgamma(b + passages) + math.lgamma(a + b) - math.lgamma(b) - math.lgamma(a + b + passages))
    return -passages * math.log1p(-(1.0 - off) * share)


def _absence(kind, key, passages, share, cfg, llr=None, **kw) -> Finding:
    """An absence finding: ``P`` passages that all missed an element taking ``share`` of them
    (``llr``: the log likelihood ratio when the caller composed it, :func:`_lane_absence`).

    Shares vary from element to element (real demand leaves lanes and turns almost empty),
    so the element's share is ``f ~ Beta(k share, k (1 - share))`` (``k`` =
    ``share_concentration``) and "no passage on it although it exists" has probability
    ``E[(1 - f)^P] = B(a, b + P) / B(a, b)``; ``k = 0``: exactly ``(1 - share)^P``."""
    share = min(max(share, 1e-9), 1.0 - 1e-9)
    llr = _absence_llr(passages, share, cfg) if llr is None else llr
    prior = math.log(cfg.absence_prior / (1.0 - cfg.absence_prior))
    conf = 1.0 / (1.0 + math.exp(-min(max(llr + prior, -50.0), 50.0)))
    ev = {'passages': passages, 'share': share, **kw.pop('evidence', {})}
    return Finding(kind, key, conf, evidence=ev, log_lr=llr, prior=prior, **kw)


def _est_lanes(lanelets) -> tuple[dict, dict]:
    """(arm, direction) -> estimated lanelets by lane index; id -> lanelet."""
    by = {}
    for l in lanelets:
        if l.kind in ('entering', 'leaving'):
            d = ENTERING if l.kind == 'entering' else LEAVING
            by.setdefault((l.arm, d), []).append(l)
    return {k: sorted(v, key=lambda l: l.lane_index) for k, v in by.items()}, {l.id: l for l in lanelets}


def _sector(angle: float, mapped) -> int:
    """The mapped arm an unmatched estimated arm follows counter-clockwise (key of arm_added)."""
    ang = np.array([a.angle for a in mapped.arms])
    if not len(ang):
        return -1
    return int(np.argmin((angle - ang) % (2 * math.pi)))


def _arm_findings(est, mapped, amap, conf, pas, cfg, arm_moves=None) -> list:
    """Arms added (estimated, unmatched) and removed (mapped, unmatched: :func:`_arm_absence`
    with ``arm_moves``, the drive's turns in mapped arms)."""
    out = []
    total = float(sum(pas))
    for e, arm in enumerate(est.arms):
        if e not in amap:
            s = _sector(arm.angle, mapped)
            out.append(_positive('arm_added', f'arm_added:after{s}', conf[e], cfg, map_arm=s,
                                 evidence={'passages': pas[e], 'angle_deg': math.degrees(arm.angle)}))
    matched = set(amap.values())
    for m in range(len(mapped.arms)):
        if m not in matched:
            out.append(_arm_absence(m, mapped, total, arm_moves, cfg))
    return out


def _arm_absence(m: int, mapped, total: float, arm_moves, cfg) -> Finding:
    """``arm_removed`` for mapped arm ``m``: the absence likelihood of the vehicles whose turn
    the drive saw (the lane rule's turn reasoning, :func:`_lane_absence`, one level up).

    A vehicle's turn is one of the map's arm-to-arm turns; the drive's turn shares are
    unknown, ``Dirichlet(MOVE_PRIOR)`` over the mapped turns, so the share of the turns into
    and out of ``m`` is ``S ~ Beta(MOVE_PRIOR |T_m|, MOVE_PRIOR |T \\ T_m|)``, and ``K``
    vehicles whose turns were seen all avoiding ``m`` have probability ``E[(1 - S)^K]``
    (:func:`_unknown_turn_llr` with ``h = 1``). A vehicle seen on one arm only says nothing:
    it may have come from or gone to ``m`` out of sight (short recordings, sensor range).
    Why: the three AV2 recordings claimed mapped arms removed that no vehicle of the 11 s
    clip had a reason to drive, from every passage of the main road (share ``1 / arms``).

    ``arm_moves`` None (no turns known: raw detections) or ``turn_absence`` 0: the rule
    before, every arm passage of the drive missed it with share ``1 / arms``."""
    lanes = [l.id for l in mapped.arms[m].lanes_in + mapped.arms[m].lanes_out]
    turns = {(c.key[0], c.key[2]) for c in mapped.connectors}
    mine = {t for t in turns if m in t}
    if not cfg.turn_absence or arm_moves is None or not mine or mine == turns:
        return _absence('arm_removed', f'arm_removed:{m}', total, 1.0 / len(mapped.arms), cfg,
                        map_arm=m, map_lanes=lanes)
    k = float(sum(n for (a, b), n in arm_moves.items() if m not in (a, b)))
    A, B = MOVE_PRIOR * len(mine), MOVE_PRIOR * len(turns - mine)
    return _absence('arm_removed', f'arm_removed:{m}', k, A / (A + B), cfg, llr=_unknown_turn_llr(k, A, B, 1.0),
                    map_arm=m, map_lanes=lanes,
                    evidence={'vehicles_known_turn': k, 'turns_mapped': len(turns), 'turns_of_arm': len(mine)})


def _distances(est_l, map_l) -> np.ndarray:
    """``(len(est_l), len(map_l))`` :func:`lane_distance` of every estimated lane to every
    mapped lane, in one pass per mapped lane (the node compares at every lane update)."""
    if not est_l or not map_l:
        return np.zeros((len(est_l), len(map_l)))
    return _cost_matrix([resample(np.asarray(e.center, float)) for e in est_l],
                        [np.asarray(m.center, float) for m in map_l]).T


def _pair_lanes(cost) -> dict[int, int]:
    """Estimated lane -> mapped lane by center-line distance (Hungarian) from their
    :func:`_distances` (None or empty: no pair)."""
    if cost is None or not cost.size:
        return {}
    cost = np.where(np.isfinite(cost), cost, 1e6)
    r, c = linear_sum_assignment(cost)
    return {int(i): int(j) for i, j in zip(r, c)}


def _lane_identity(e, m, est_lanes, mapped) -> tuple[dict, dict]:
    """``{(direction, estimated lane_index): mapped lane index}`` of estimated arm ``e`` and
    mapped arm ``m``: which mapped lane an estimated lane *is*, by position, not by index;
    and per direction the :func:`_distances` of its estimated lanes to the mapped lanes of
    that direction (for :func:`_pair_lanes`: computed once per lane update).

    An estimated lane is a mapped lane when each is the other's nearest (mean center-line
    distance, :func:`lane_distance`), the estimated lane's nearest taken over the mapped
    arm's lanes of *both* directions. Lanes of one road do not overlap, so an estimated lane
    nearer another mapped lane than its own lies in that lane's space: its index says nothing
    about which mapped lane it is. The estimator makes exactly this error in short drives
    (an empty lane added on one side of a direction and its lanes shifted by one, the lane
    count unchanged): paired by index, the shifted lanes read as "moved" by a lane width and
    their turns as turns the map lacks (docs/fleet.md, rule 6)."""
    marm = mapped.arms[m]
    ml = [(d, j, l) for d in (ENTERING, LEAVING) for j, l in enumerate(marm.lanes(d))]
    out, blocks = {}, {}
    for d in (ENTERING, LEAVING):
        el = est_lanes.get((e, d), [])
        if not el or not ml:
            continue
        cost = _distances(el, [y for _, _, y in ml])
        blocks[d] = cost[:, [k for k, (dm, _, _) in enumerate(ml) if dm == d]]
        cost[~np.isfinite(cost)] = np.inf
        for i, x in enumerate(el):
            if not np.isfinite(cost[i]).any():
                continue
            c = int(np.argmin(cost[i]))
            dm, j, _ = ml[c]
            if dm == d and int(np.argmin(cost[:, c])) == i:
                out[(d, x.lane_index)] = j
    return out, blocks


def _with_traffic(el) -> list:
    """Estimated lanes a vehicle drove (``support``; all of them when the estimate carries no
    support, e.g. raw radar input)."""
    return [l for l in el if l.support > 0] if any(l.support > 0 for l in el) else list(el)


def _lane_findings(e, m, est, mapped, lanes, conf, pas, cfg, counts_ok, lanes_seen, lane_conf,
                   ident, costs, moves, p_dirs=None, choices=None) -> list:
    """Lane findings of estimated arm ``e`` against mapped arm ``m``; ``ident``, ``costs``: that
    arm pair's :func:`_lane_identity` (lane identities; per direction the lane distances);
    ``moves``: :func:`_movements`; ``p_dirs``: the passages of each (arm, direction) when the
    traffic was counted on the map (else from the arm's confidence); ``choices``: the drive's
    lane choices (:func:`_choice_groups`; None: ``share_concentration``)."""
    out = []
    arm, marm = est.arms[e], mapped.arms[m]
    for d, n_est in ((ENTERING, arm.lanes_in), (LEAVING, arm.lanes_out)):
        ml, el, ds = marm.lanes(d), lanes.get((e, d), []), DIRS[d]
        ev = {'passages': pas[e], 'lanes_estimated': int(n_est), 'lanes_mapped': len(ml)}
        pair = _pair_lanes(costs.get(d))
        has_support = any(l.support > 0 for l in lanes.get((e, ENTERING), []) + lanes.get((e, LEAVING), []))
        if lanes_seen is not None:
            # the mapped lanes the drive's vehicles drove: estimated lanes with traffic that
            # *are* that lane by position (_lane_identity; the Hungarian pair also joins lanes
            # a lane width or more apart)
            lanes_seen.update(ml[ident[(d, l.lane_index)]].id for l in _with_traffic(el) if (d, l.lane_index) in ident)
        if lane_conf is not None:
            # per-vehicle evidence of the lane's course, as a probability: logit = support / 3
            lane_conf.update({ml[j].id: (1.0 / (1.0 + math.exp(-el[i].support / 3.0)) if has_support else conf[e])
                              for i, j in pair.items()})
        if n_est > len(ml):
            # the evidence of a lane the map lacks is the traffic on the estimated lane(s) no
            # mapped lane pairs with (an estimated lane no vehicle drove shows nothing)
            extra = [el[i] for i in range(len(el)) if i not in pair]
            veh = sum(l.support for l in extra) if has_support and extra else None
            out.append(_positive('lane_added', f'lane_added:{m}{ds}', conf[e], cfg, veh, map_arm=m, direction=ds,
                                 evidence={**ev, 'support_extra': int(sum(l.support for l in extra))}))
        elif n_est < len(ml):
            gone = [ml[j].id for j in range(len(ml)) if j not in pair.values()] if pair else [l.id for l in ml[n_est:]]
            # the arm's passages in this direction (by mapped lanes) all missed the missing lane;
            # one finding per mapped lane (key = its id), so that drives missing *different*
            # lanes of one arm do not add up to one lane "removed", and a drive that drove the
            # lane refutes it (DriveView.lanes_seen)
            p_dir = pas[e] * len(ml) / max(len(marm.lanes_in) + len(marm.lanes_out), 1)
            if p_dirs is not None:
                p_dir = p_dirs.get((e, d), 0.0)
            index = {l.id: j for j, l in enumerate(ml)}
            conc = None if choices is None else lane_choice(choices, (m, d), cfg.empty_prior)
            for g in gone:
                out.append(_lane_absence(g, index[g], m, d, p_dir, len(ml), mapped,
                                         moves.get((e, d), {}), cfg, conc, map_arm=m, direction=ds, evidence=ev))
        else:
            counts_ok.add((m, ds))
            # the mapped lane each estimated lane is by position (not its index: a lane in
            # another mapped lane's space has not "moved" there, _lane_identity)
            for k, el_k in enumerate(el):
                if (d, el_k.lane_index) not in ident:
                    continue
                ml_k = ml[ident[(d, el_k.lane_index)]]
                dist = lane_distance(el_k.center, ml_k.center)
                if math.isfinite(dist) and dist > cfg.moved_m:
                    # as sure as the estimated lane's course: the vehicles that drove it
                    veh = el_k.support if has_support else None
                    out.append(_positive('lane_moved', f'lane_moved:{ml_k.id}', conf[e], cfg, veh, map_arm=m,
                                         direction=ds, map_lanes=[ml_k.id],
                                         evidence={'passages': pas[e], 'offset_m': dist, 'lane_index': k,
                                                   'support': int(el_k.support)}))
    return out


def _movements(by_id: dict, amap: dict) -> dict:
    """``(estimated arm, direction) -> {mapped arm: vehicles}``: where the drive's vehicles of
    that arm direction went to (entering) or came from (leaving), from the estimated
    connectors and the vehicles that took them (``support``; paper §III: connectors exist only
    where trajectories drove them)."""
    out: dict = {}
    for l in by_id.values():
        if l.kind != 'connector' or l.arm not in amap or l.arm_to not in amap:
            continue
        for (e, d, other) in ((l.arm, ENTERING, amap[l.arm_to]), (l.arm_to, LEAVING, amap[l.arm])):
            per = out.setdefault((e, d), {})
            per[other] = per.get(other, 0.0) + float(l.support)
    return out


def _lane_moves(traffic, arm, d: int) -> dict:
    """Mapped arm -> vehicles seen on a lane of ``arm``, direction ``d``, turning to (entering)
    or coming from (leaving) it (``traffic.lane_turns`` summed over the direction's lanes)."""
    out: dict = {}
    ids = {l.id for l in arm.lanes(d)}
    for (lid, other), n in traffic.lane_turns.items():
        if lid in ids:
            out[other] = out.get(other, 0.0) + float(n)
    return out


def _served(mapped, m: int, d: int) -> dict:
    """Mapped lane index of arm ``m``, direction ``d`` -> the mapped arms its mapped turns lead
    to (entering) or come from (leaving)."""
    out: dict = {}
    for c in mapped.connectors:
        a, i, b, j = c.key
        if d == ENTERING and a == m:
            out.setdefault(i, set()).add(b)
        elif d == LEAVING and b == m:
            out.setdefault(j, set()).add(a)
    return out


#: Dirichlet pseudo count per mapped turn of a direction in the drive's turn shares (Jeffreys)
MOVE_PRIOR = 0.5


def _unknown_turn_llr(passages: float, a: float, b: float, h: float, k: float = 0.0) -> float:
    """Log LR "gone" of ``passages`` whose turns were not seen, all of which missed a lane that
    takes a share ``h * pi`` of them, ``pi ~ Beta(a, b)`` the share of the turns it serves:
    ``-ln E[(1 - h pi)^P] = -ln 2F1(-P, a; a + b; h)`` (``h = 1``: ``B(a, b + P) / B(a, b)``).
    ``k`` > 0: the lane's share of its turns varies too, ``Beta(k h, k (1 - h))``, and the
    expectation is taken over it at :data:`_QUAD` quantiles."""
    if passages <= 0.0:
        return 0.0
    h = min(max(h, 1e-9), 1.0 - 1e-9)
    hs = beta_dist.ppf(_QUAD, k * h, k * (1.0 - h)) if k > 0 else np.array([h])
    return -math.log(max(float(np.mean(hyp2f1(-passages, a, a + b, np.clip(hs, 0.0, 1.0)))), 1e-300))


#: quantile levels of the expectation over a lane's share in :func:`_unknown_turn_llr`
_QUAD = (np.arange(32) + 0.5) / 32
#: lane-choice concentrations a drive is read among (:func:`lane_concentration`); beyond the
#: last, exact shares (multinomial) are taken
CONCENTRATIONS = np.geomspace(0.05, 500.0, 41)


def _choice_groups(traffic, mapped) -> tuple[dict, dict, dict]:
    """What the drive's vehicles showed of their lane choice, per ``(mapped arm, direction)``:
    the lane counts of every mapped turn that two or more mapped lanes of the direction serve
    (the vehicles seen driving each of those lanes taking it, ``traffic.lane_turns``; turns
    with fewer than two such vehicles show no choice), and ``[off, seen]``: of the vehicles
    seen on a lane of the direction taking a mapped turn, how many were on a lane the map does
    not give that turn (a late lane change, a matching slip); and per direction its lanes'
    emptiness against their turns' vehicles (:func:`_empty_lanes`, for :func:`empty_ratio`)."""
    groups: dict = {}
    off: dict = {}
    empties: dict = {}
    for a in mapped.arms:
        for d in (ENTERING, LEAVING):
            ml = a.lanes(d)
            served = _served(mapped, a.index, d)
            turns: dict = {}            # turn -> (vehicles taking it from its lanes, its lanes)
            for b, lanes in _turn_lanes(served).items():
                c = [traffic.lane_turns.get((ml[j].id, b), 0) for j in lanes if j < len(ml)]
                turns[b] = (sum(c), len(lanes))
                if len(c) >= 2 and sum(c) >= 2:
                    groups.setdefault((a.index, d), []).append(np.asarray(c, float))
                n = [traffic.lane_turns.get((l.id, b), 0) for l in ml]
                bad = sum(x for j, x in enumerate(n) if b not in served.get(j, ()))
                if sum(n):
                    tot = off.setdefault((a.index, d), [0, 0])
                    tot[0], tot[1] = tot[0] + bad, tot[1] + sum(n)
            empties[(a.index, d)] = _empty_lanes(traffic, ml, served, turns)
    return groups, off, empties


def _empty_lanes(traffic, ml, served: dict, turns: dict) -> list:
    """``[(empty, [(K_b, n_b), ...]), ...]`` per mapped lane of one direction whose turns the
    drive's vehicles took: whether none of them drove the lane, and per turn it serves the
    vehicles seen taking that turn from the direction's lanes and the mapped lanes serving it
    (``turns``: those pairs per turn)."""
    out = []
    for j, mine in sorted(served.items()):
        if j >= len(ml):
            continue
        kb = [turns[b] for b in sorted(mine)]
        if sum(k for k, _ in kb) >= 1:
            out.append((all(traffic.lane_turns.get((ml[j].id, b), 0) == 0 for b in mine), kb))
    return out


def _turn_lanes(served: dict) -> dict:
    """Mapped turn -> the lane indices that serve it (:func:`_served` turned around)."""
    out: dict = {}
    for j, turns in sorted(served.items()):
        for b in turns:
            out.setdefault(b, []).append(j)
    return out


def _choice_loglik(c: np.ndarray) -> np.ndarray:
    """Log likelihood of one turn's lane counts ``c`` under a symmetric Dirichlet-multinomial
    of concentration ``k`` (each lane ``k / n``), per :data:`CONCENTRATIONS`, and last under
    exact equal shares (the multinomial); the multinomial coefficient, common to all, left out."""
    n, K = len(c), float(c.sum())
    k = CONCENTRATIONS[:, None]
    dm = (gammaln(k[:, 0]) - gammaln(k[:, 0] + K)
          + np.sum(gammaln(k / n + c[None, :]) - gammaln(k / n), axis=1))
    return np.r_[dm, -K * math.log(n)]


@dataclass(frozen=True)
class LaneChoice:
    """How the drive's vehicles chose their lanes (:func:`lane_choice`): ``post`` the posterior
    ``[(k, weight), ...]`` of the concentration of a lane's share of a turn (``k = 0``: exact
    equal shares); ``off`` the probability that a vehicle is seen on a lane the map does not
    give its turn; ``empty_ratio`` how often a lane stands empty against that model's
    expectation (:func:`empty_ratio`)."""

    post: tuple
    off: float = 0.0
    empty_ratio: float = 1.0


def lane_concentration(groups: dict, skip) -> list:
    """How evenly the drive's vehicles chose among mapped lanes serving the same turn: the
    posterior ``[(k, weight), ...]`` over :data:`CONCENTRATIONS` and exact shares (``k = 0``,
    the model without spread), a flat prior over those points and the likelihood
    :func:`_choice_loglik` of every arm direction but ``skip`` (the one whose lane is judged:
    its own empty lane must not vouch for itself). Real drivers, and SUMO's, keep to one lane
    of a turn; Table I's routes pick uniformly -- the drive says which world it is in, and a
    drive that shows few choices leaves it open (the prior)."""
    ll = np.zeros(len(CONCENTRATIONS) + 1)
    for key, cs in groups.items():
        if key != skip:
            for c in cs:
                ll += _choice_loglik(c)
    w = np.exp(ll - ll.max())
    w /= w.sum()
    return [(float(k), float(p)) for k, p in zip(np.r_[CONCENTRATIONS, 0.0], w) if p > 1e-6]


def lane_choice(choices: tuple[dict, dict, dict], skip, empty_prior: float = 1.0) -> LaneChoice:
    """:class:`LaneChoice` of the drive from :func:`_choice_groups`, every arm direction but
    ``skip``: the concentration's posterior (:func:`lane_concentration`), the off-map share,
    the posterior mean under a Jeffreys prior, ``(off + 0.5) / (seen + 1)``, and the empty-lane
    ratio (:func:`empty_ratio`, ``empty_prior`` pseudo lanes)."""
    groups, off, empties = choices
    bad = sum(v[0] for key, v in off.items() if key != skip)
    seen = sum(v[1] for key, v in off.items() if key != skip)
    post = tuple(lane_concentration(groups, skip))
    eps = (bad + 0.5) / (seen + 1.0)
    return LaneChoice(post, eps, empty_ratio(empties, skip, post, eps, empty_prior))


def empty_ratio(empties: dict, skip, post, off: float, prior: float = 1.0) -> float:
    """How often the drive's mapped lanes (every arm direction but ``skip``) stood empty
    against how often the lane-choice model expects it, ``(E + a) / (P + a)``: ``E`` the
    lanes none of whose turns' vehicles drove them, ``P`` the sum of the model's probabilities
    of that (:func:`_absence_llr` per turn the lane serves, averaged over the concentration
    ``post``), ``a = prior`` pseudo lanes that stood empty as often as the model says (the
    posterior mean of the ratio under a ``Gamma(a, a)`` prior of mean 1). A world whose routes
    cover every lane shows fewer empty lanes than random lane choice makes, and an empty lane
    there is stronger evidence; a world that leaves lanes empty beyond the model weakens it."""
    E = P = 0.0
    for key, lanes in empties.items():
        if key == skip:
            continue
        for empty, kb in lanes:
            E += float(empty)
            P += math.exp(-_mixed(post, lambda k, kb=kb: sum(_absence_llr(K, 1.0 / n, None, k, off)
                                                            for K, n in kb)))
    return (E + prior) / (P + prior)


def _lane_absence(lane_id, j, m, d, p_dir, n_lanes, mapped, moves, cfg, conc=None, **kw) -> Finding:
    """``lane_removed`` for mapped lane ``j`` of arm ``m``, direction ``d``: the absence
    likelihood of the passages that *could* have used it.

    A lane serves the turns the map gives it, and a vehicle takes a lane that leads where it
    goes. Real demand is lumpy over turns: SUMO leaves 24 % of the lanes of a used direction
    without a vehicle, most of them lanes of turns nobody took in the recording. So:

    * the ``K_b`` vehicles seen taking a turn ``b`` the lane serves (estimated connectors)
      each missed a lane taking ``1 / n_b`` of that turn (``n_b`` mapped lanes of the
      direction serve ``b``): ``(1 - 1 / n_b)^K_b``; a vehicle seen taking another turn
      says nothing about the lane;
    * the direction's other ``U = p_dir - sum_b K_b`` passages (turn not seen) took the
      lane's turns with share ``pi ~ Beta(A, B)`` -- the turn shares of the drive are
      ``Dirichlet(MOVE_PRIOR + K)`` over the mapped turns, ``A`` summed over the lane's
      turns, ``B`` over the others -- and then this lane with probability ``h`` (the
      ``1 / n_b`` averaged over its turns): :func:`_unknown_turn_llr`.

    A mapped lane without mapped turns could have taken any vehicle of its direction:
    ``(1 - 1 / n_lanes)^p_dir``, the rule before.

    ``conc``: the drive's :class:`LaneChoice` (None: ``share_concentration``, nothing seen
    off the map's lanes); the likelihood is averaged over its concentration, and a vehicle
    is seen off its lane with its ``off`` share."""
    served = _served(mapped, m, d) if cfg.turn_absence else {}
    mine = served.get(j, set())
    post = ((cfg.share_concentration, 1.0),) if conc is None else conc.post
    eps = 0.0 if conc is None else conc.off
    kw['evidence'] = {**kw.get('evidence', {}), 'lane_off_share': eps,
                      'lane_choice_concentration': max(post, key=lambda kp: kp[1])[0],
                      'lane_choice_post': [tuple(kp) for kp in post]}    # fusion pools it
    if not mine:
        llr = _mixed(post, lambda k: _absence_llr(p_dir, 1.0 / n_lanes, cfg, k))
        return _absence('lane_removed', f'lane_removed:{lane_id}', p_dir, 1.0 / n_lanes, cfg,
                        llr=llr, map_lanes=[lane_id], **kw)
    offered = set().union(*served.values())
    n_b = {b: sum(b in s for s in served.values()) for b in offered}
    k = {b: moves.get(b, 0.0) for b in offered}
    known = sum(k.values())
    unknown = max(p_dir - known, 0.0)
    A = sum(k[b] + MOVE_PRIOR for b in mine)
    B = sum(k[b] + MOVE_PRIOR for b in offered - mine)
    h = sum((k[b] + MOVE_PRIOR) / n_b[b] for b in mine) / A
    seen = sum(k[b] for b in mine)                 # vehicles seen taking the lane's turns
    llr = _mixed(post, lambda c: sum(_absence_llr(k[b], 1.0 / n_b[b], cfg, c, eps) for b in mine)
                 + _unknown_turn_llr(unknown, A, B, (1.0 - eps) * h, c))
    if cfg.empty_calibration and conc is not None and llr > 0.0 and seen >= 1:
        # the ratio is read on lanes whose turns some vehicle was seen taking (_empty_lanes):
        # it speaks for a lane with such vehicles, not for one shown by unseen turns alone
        llr -= math.log(conc.empty_ratio)
        kw['evidence']['empty_ratio'] = conc.empty_ratio
    share = h * A / (A + B)
    passages = seen + unknown * share
    kw['evidence'] = {**kw.get('evidence', {}), 'turns_served': sorted(mine), 'passages_turns': known,
                      'vehicles_its_turns': seen, 'passages_unknown_turn': unknown}
    return _absence('lane_removed', f'lane_removed:{lane_id}', passages, share, cfg, llr=llr,
                    map_lanes=[lane_id], **kw)


def _mixed(post, llr_at) -> float:
    """Log LR "gone" averaged over a posterior ``[(k, weight), ...]`` of the share's
    concentration: ``-ln sum_k w_k exp(-llr(k))`` (the likelihoods, not their logs, average)."""
    terms = [math.log(w) - llr_at(k) for k, w in post]
    top = max(terms)
    return -(top + math.log(sum(math.exp(t - top) for t in terms)))


def _connector_findings(est, mapped, amap, lanes_by_id, conf, pas, cfg, counts_ok, used, ident) -> list:
    """Turns in *mapped* lane indices: an estimated connector's entering and leaving lanes are
    the mapped lanes they lie on (``ident``, :func:`_lane_identity`); a turn from or to an
    estimated lane that is no mapped lane cannot be placed and shows nothing."""
    out, keys = [], {c.key: c for c in mapped.connectors}
    seen = set()
    for l in lanes_by_id.values():
        if l.kind != 'connector' or l.arm not in amap or l.arm_to not in amap or not l.successors:
            continue
        a, b = amap[l.arm], amap[l.arm_to]
        nxt = lanes_by_id.get(l.successors[0])
        if nxt is None or (a, 'in') not in counts_ok or (b, 'out') not in counts_ok:
            continue
        i, j = ident.get(l.arm, {}).get((ENTERING, l.lane_index)), ident.get(l.arm_to, {}).get((LEAVING, nxt.lane_index))
        if i is None or j is None:
            continue
        key = (a, i, b, j)
        seen.add(key)
        if key in keys:
            used.add(keys[key].id)
        else:
            c = min(conf[l.arm], conf[l.arm_to])
            veh = l.support if any(x.support > 0 for x in lanes_by_id.values()) else None   # who took the turn
            out.append(_positive('connector_added', 'connector_added:%d.%d-%d.%d' % key, c, cfg, veh, map_arm=a,
                                 direction='in',
                                 map_lanes=[mapped.arms[a].lanes_in[key[1]].id, mapped.arms[b].lanes_out[key[3]].id],
                                 evidence={'passages': min(pas[l.arm], pas[l.arm_to]), 'turn': list(key)}))
    n_next: dict = {}
    for c in mapped.connectors:
        n_next[c.lane_in] = n_next.get(c.lane_in, 0) + 1
    left_by = {(k[0], k[1]) for k in seen}       # entering lanes the drive's vehicles left by a known turn
    for key, c in sorted(keys.items()):
        a, b = key[0], key[2]
        if key in seen or (a, 'in') not in counts_ok or (b, 'out') not in counts_ok or (a, key[1]) not in left_by:
            continue
        # passages known to have gone through the entering lane: one per turn seen from it
        # (a lower bound: the estimate does not say how many vehicles took each turn)
        lane_pas = float(sum(1 for k in seen if k[:2] == key[:2]))
        out.append(_absence('connector_unused', f'connector_unused:{c.id}', lane_pas, 1.0 / n_next[c.lane_in],
                            cfg, map_arm=a, direction='in', map_lanes=[c.id, c.lane_in]))
    return out


def compare(est, lanelets, mapped, cfg: ChangeConfig = ChangeConfig(), traffic=None) -> DriveView:
    """Findings of one estimate (``model.Intersection`` + lanelets) against ``mapped``;
    ``traffic``: the drive's vehicles map-matched to ``mapped``
    (:func:`.corroborate.match_traffic`), which drop the findings they contradict and add
    the lanes and turns they drove to the drive's refutations."""
    conf = [float(a.confidence) for a in est.arms]
    pas = [arm_passages(c) for c in conf]
    amap = match_arms([a.angle for a in est.arms], [a.angle for a in mapped.arms], cfg.arm_gate_deg)
    lanes, by_id = _est_lanes(lanelets)
    counts_ok, used, lanes_seen, lane_conf = set(), set(), set(), {}
    pairs = {e: _lane_identity(e, m, lanes, mapped) for e, m in sorted(amap.items())}
    ident = {e: v[0] for e, v in pairs.items()}           # the connector findings need them all
    choices = _choice_groups(traffic, mapped) if traffic is not None and cfg.share_from_traffic else None
    if traffic is None:           # the turns the estimate's connectors show
        moves, p_dirs = _movements(by_id, amap), None
        known = any(l.support > 0 for l in by_id.values())      # raw detections: no vehicle counts
        arm_moves = {(amap[e], b): n for (e, d), per in moves.items() if d == ENTERING
                     for b, n in per.items()} if known else None
    else:                         # the turns and passages the vehicles showed on the map itself
        # a lane's absence: the vehicles seen on a lane of its direction taking each turn (one
        # seen in the box only chose no lane there); the arm's: every turn seen
        moves = {(e, d): _lane_moves(traffic, mapped.arms[m], d) for e, m in amap.items()
                 for d in (ENTERING, LEAVING)}
        p_dirs = {(e, d): float(traffic.passages.get((m, d), 0)) for e, m in amap.items()
                  for d in (ENTERING, LEAVING)}
        arm_moves = {(a, b): n for (a, d), per in traffic.moves.items() if d == ENTERING for b, n in per.items()}
    findings = _arm_findings(est, mapped, amap, conf, pas, cfg, arm_moves)
    for e, m in sorted(amap.items()):
        findings += _lane_findings(e, m, est, mapped, lanes, conf, pas, cfg, counts_ok, lanes_seen, lane_conf,
                                   *pairs[e], moves, p_dirs, choices)
    findings += _connector_findings(est, mapped, amap, by_id, conf, pas, cfg, counts_ok, used, ident)
    if traffic is not None:
        findings = [f for f in findings if not refutes(f, traffic, mapped, cfg.moved_m, cfg.arm_gate_deg)]
        lanes_seen.update(l for l, n in traffic.vehicles.items() if n >= 1)
        used.update(c.id for c in mapped.connectors if (c.lane_in, c.lane_out) in traffic.turns)
    total = float(sum(pas))
    weak = sorted((f for f in findings if f.confidence <= 0.5), key=lambda f: f.key)
    return DriveView(intersection=mapped.id, findings=sorted((f for f in findings if f.confidence > 0.5),
                                                             key=lambda f: f.key), weak=weak,
                     unobserved=sorted(f.map_arm for f in weak if f.kind == 'arm_removed'),
                     arm_conf={m: conf[e] for e, m in amap.items()}, counts_ok=counts_ok, used=used,
                     total_conf=1.0 - math.exp(-total / 3.0), passages=total, lanes_seen=lanes_seen,
                     lane_conf=lane_conf,
                     no_new_arm_llr=_absence('arm_added', '', total, 1.0 / (len(mapped.arms) + 1), cfg).log_lr)
