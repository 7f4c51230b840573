"""Junction networks of the SUMO family (issue 15.1): generated ones and the inD nets.

Generated (:func:`generate_net`): plain ``.nod.xml`` / ``.edg.xml`` written from a seeded
draw, built with ``netconvert``. What real junctions have and our Table I simulator does
not: 3-6 arms at skewed angles (>= ``min_arm_angle_deg`` apart), approaches that curve
(a bend of up to ``curve_deg`` starting ``curve_start_m`` out), arm axes that miss the
center by up to ``offset_m`` (arms do not meet in one point), a median gap, turn
pockets (the entering edge gains a lane ``pocket_m`` before the stop line: a split
node), a neighbouring junction ``neighbour_m`` out on one arm with a side road,
traffic lights or priority rules, sidewalks with crossings (pedestrians). The
junction under test is node ``C``; the neighbour is ``N<arm>``; split nodes ``S<arm>``.

inD (:func:`ind_net`): the four networks of ``../shared/realdata/ind_sumo`` (real
junction geometry, drawn after the inD recordings), read where they lie: never copied
into the repository. The networks inside the SUMO package are never used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import subprocess
import sys
from xml.sax.saxutils import quoteattr

import numpy as np

from .sumo_config import SumoConfig

__all__ = ['ArmPlan', 'NetPlan', 'plan_net', 'write_plain', 'generate_net', 'ind_net',
           'realdata_dir', 'sumo_binary', 'SumoError']


class SumoError(RuntimeError):
    """A SUMO tool failed (one-line message with the tool's last words)."""


@dataclass
class ArmPlan:
    angle: float
    lanes_in: int
    lanes_out: int
    width: float
    gap: float
    path: np.ndarray                 # outward polyline from the approach start
    pocket_m: float = 0.0            # > 0: the entering edge gains a lane this far out
    neighbour_m: float = 0.0         # > 0: neighbouring junction this far out
    side_angle: float = 0.0


@dataclass
class NetPlan:
    arms: list[ArmPlan] = field(default_factory=list)
    tls: bool = False


def sumo_binary(name: str) -> str:
    """Path of a SUMO tool from the pinned ``eclipse-sumo`` wheel (no system SUMO)."""
    import sumo
    p = Path(sumo.SUMO_HOME) / 'bin' / name
    if not p.exists():
        raise SumoError(f'{name} not found in {p.parent} (pip install eclipse-sumo==1.28.0)')
    return str(p)


def realdata_dir() -> Path:
    """``$IE_REALDATA`` if set, else the first existing ``shared/realdata`` beside the checkout
    (CI lays shared/ beside the clone): beside the source tree, beside the checkout whose
    ``.venv`` runs this (an installed copy), beside the working directory; the source tree's
    candidate when none exists (the caller's error then names it)."""
    env = os.environ.get('IE_REALDATA')
    if env:
        return Path(env)
    tail = Path('shared') / 'realdata'
    cands = [Path(__file__).resolve().parents[2].parent / tail,
             Path(sys.prefix).resolve().parent.parent / tail,
             Path.cwd().resolve().parent / tail, Path.cwd().resolve() / tail]
    return next((c for c in cands if c.is_dir()), cands[0])


def _angles(rng, n, min_deg):
    slack = 2 * math.pi - n * math.radians(min_deg)
    gaps = math.radians(min_deg) + slack * rng.dirichlet(np.ones(n))
    return np.sort((rng.uniform(-math.pi, math.pi) + np.cumsum(gaps) + math.pi)
                   % (2 * math.pi) - math.pi)


def _path(rng, angle, cfg: SumoConfig) -> np.ndarray:
    """Outward polyline: from the approach start (``box_m`` out, ``offset`` aside),
    straight, then a bend of ``beta`` over 50 m, then straight to ``arm_length_m``."""
    u = np.array([math.cos(angle), math.sin(angle)])
    n = np.array([-u[1], u[0]])
    p = float(rng.uniform(*cfg.box_m)) * u + float(rng.uniform(-cfg.offset_m, cfg.offset_m)) * n
    s_bend = float(rng.uniform(*cfg.curve_start_m))
    beta = math.radians(float(rng.uniform(-cfg.curve_deg, cfg.curve_deg)))
    step, h, pts = 2.0, angle, [p]
    for i in range(int((cfg.arm_length_m - cfg.box_m[0]) / step)):
        if s_bend <= i * step < s_bend + 50.0:
            h += beta * step / 50.0
        p = p + step * np.array([math.cos(h), math.sin(h)])
        pts.append(p)
    return np.array(pts)


def plan_net(rng: np.random.Generator, cfg: SumoConfig) -> NetPlan:
    """Draw a generated junction (module doc)."""
    n = int(rng.integers(cfg.arms[0], cfg.arms[1] + 1))
    plan = NetPlan(tls=bool(rng.uniform() < cfg.tls_prob))
    neighbour = int(rng.integers(n)) if rng.uniform() < cfg.neighbour_prob else -1
    for a, ang in enumerate(_angles(rng, n, cfg.min_arm_angle_deg)):
        li, lo = (int(x) for x in rng.integers(cfg.lanes[0], cfg.lanes[1] + 1, size=2))
        arm = ArmPlan(angle=float(ang), lanes_in=li, lanes_out=lo,
                      width=float(rng.uniform(*cfg.lane_width)),
                      gap=float(rng.uniform(*cfg.median_gap)), path=_path(rng, ang, cfg))
        pocket = rng.uniform() < cfg.pocket_prob
        if a == neighbour:
            arm.neighbour_m = float(rng.uniform(*cfg.neighbour_m))
            arm.side_angle = float(ang + rng.choice([-1, 1]) * math.radians(rng.uniform(60, 120)))
        elif pocket:
            arm.pocket_m = float(rng.uniform(*cfg.pocket_m))
        plan.arms.append(arm)
    return plan


def _shift_right(path: np.ndarray, d: float) -> np.ndarray:
    t = np.gradient(path, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return path + d * np.stack([t[:, 1], -t[:, 0]], axis=1)


def _cut(path: np.ndarray, s: float):
    """Split a polyline at arc length s -> (head incl. the cut point, tail from it)."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    j = int(np.clip(np.searchsorted(arc, s), 1, len(path) - 1))
    f = (s - arc[j - 1]) / max(arc[j] - arc[j - 1], 1e-9)
    q = path[j - 1] + f * (path[j] - path[j - 1])
    return np.vstack([path[:j], q]), np.vstack([q, path[j:]])


def _shape(pts) -> str:
    return ' '.join(f'{x:.2f},{y:.2f}' for x, y in pts)


def _edge(eid, fr, to, lanes, width, shape, prio=2, speed=13.89, sidewalk=True) -> str:
    sw = ' sidewalkWidth="2.0"' if sidewalk else ''
    return (f'  <edge id="{eid}" from="{fr}" to="{to}" numLanes="{lanes}" width="{width:.2f}" '
            f'priority="{prio}" speed="{speed}" shape={quoteattr(_shape(shape))}{sw}/>')


def _main_arms(plan: NetPlan) -> set:
    """The two arms closest to opposite: the main road (higher priority)."""
    n = len(plan.arms)
    best = max(((abs(math.remainder(plan.arms[i].angle - plan.arms[j].angle, 2 * math.pi)), i, j)
                for i in range(n) for j in range(i + 1, n)))
    return {best[1], best[2]}


def _arm_xml(a: int, arm: ArmPlan, cfg: SumoConfig, prio: int):
    """(node lines, edge lines) of one arm (module doc: ids)."""
    w, li, lo = arm.width, arm.lanes_in, arm.lanes_out
    nodes = [f'  <node id="O{a}" x="{arm.path[-1, 0]:.2f}" y="{arm.path[-1, 1]:.2f}" type="priority"/>']
    out_l = _shift_right(arm.path, arm.gap / 2)              # outward, C -> O
    in_l = _shift_right(arm.path[::-1], arm.gap / 2)         # inward, O -> C
    c = np.zeros((1, 2))
    edges = []
    if arm.neighbour_m > 0:
        s = arm.neighbour_m - float(np.linalg.norm(arm.path[0]))
        (near, far) = _cut(arm.path, s)
        nx, ny = near[-1]
        d = near[-1] + 100.0 * np.array([math.cos(arm.side_angle), math.sin(arm.side_angle)])
        nodes += [f'  <node id="N{a}" x="{nx:.2f}" y="{ny:.2f}" type="priority"/>',
                  f'  <node id="D{a}" x="{d[0]:.2f}" y="{d[1]:.2f}" type="priority"/>']
        o_near, o_far = _cut(out_l, s)
        i_far, i_near = _cut(in_l, float(np.linalg.norm(np.diff(in_l, axis=0), axis=1).sum()) - s)
        side = np.stack([near[-1], d])
        edges += [_edge(f'out{a}', 'C', f'N{a}', lo, w, np.vstack([c, o_near]), prio),
                  _edge(f'out{a}b', f'N{a}', 'O' + str(a), lo, w, o_far, prio),
                  _edge(f'in{a}b', f'O{a}', f'N{a}', li, w, i_far, prio),
                  _edge(f'in{a}', f'N{a}', 'C', li, w, np.vstack([i_near, c]), prio),
                  _edge(f'side{a}in', f'D{a}', f'N{a}', 1, w, _shift_right(side[::-1], 0.0), 1, 8.33),
                  _edge(f'side{a}out', f'N{a}', f'D{a}', 1, w, _shift_right(side, 0.0), 1, 8.33)]
        return nodes, edges
    edges.append(_edge(f'out{a}', 'C', f'O{a}', lo, w, np.vstack([c, out_l]), prio))
    if arm.pocket_m > 0:
        length = float(np.linalg.norm(np.diff(in_l, axis=0), axis=1).sum())
        head, tail = _cut(in_l, length - arm.pocket_m)
        nodes.append(f'  <node id="S{a}" x="{head[-1, 0]:.2f}" y="{head[-1, 1]:.2f}" type="priority"/>')
        edges += [_edge(f'in{a}', f'O{a}', f'S{a}', li, w, head, prio),
                  _edge(f'in{a}p', f'S{a}', 'C', li + 1, w, np.vstack([tail, c]), prio)]
    else:
        edges.append(_edge(f'in{a}', f'O{a}', 'C', li, w, np.vstack([in_l, c]), prio))
    return nodes, edges


def write_plain(plan: NetPlan, cfg: SumoConfig, folder: Path) -> tuple[Path, Path]:
    """``net.nod.xml`` + ``net.edg.xml`` of a plan."""
    folder = Path(folder)
    main = _main_arms(plan)
    ctype = 'traffic_light' if plan.tls else 'priority'
    nodes, edges = [f'  <node id="C" x="0.00" y="0.00" type="{ctype}"/>'], []
    for a, arm in enumerate(plan.arms):
        nd, ed = _arm_xml(a, arm, cfg, 3 if a in main else 2)
        nodes += nd
        edges += ed
    nod, edg = folder / 'net.nod.xml', folder / 'net.edg.xml'
    nod.write_text('<nodes>\n' + '\n'.join(nodes) + '\n</nodes>\n')
    edg.write_text('<edges>\n' + '\n'.join(edges) + '\n</edges>\n')
    return nod, edg


def run_tool(args: list[str], what: str) -> None:
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise SumoError(f'{what}: {e}') from None
    if r.returncode != 0:
        last = (r.stderr or r.stdout).strip().splitlines()[-1:] or ['(no output)']
        raise SumoError(f'{what} failed ({r.returncode}): {last[0]}')


def generate_net(rng: np.random.Generator, cfg: SumoConfig, folder) -> tuple[Path, NetPlan]:
    """Draw, write and ``netconvert`` a generated junction -> (net.xml, plan)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    plan = plan_net(rng, cfg)
    nod, edg = write_plain(plan, cfg, folder)
    net = folder / 'net.net.xml'
    run_tool([sumo_binary('netconvert'), '-n', str(nod), '-e', str(edg), '-o', str(net),
              '--no-turnarounds', 'true', '--offset.disable-normalization', 'true',
              '--crossings.guess', 'true', '--junctions.corner-detail', '5',
              '--tls.default-type', 'static', '--no-warnings', 'true'], 'netconvert')
    return net, plan


def ind_net(k: int) -> tuple[Path, Path]:
    """(net.xml, rou.xml) of inD network ``k`` in 1..4 (read in place)."""
    d = realdata_dir() / 'ind_sumo'
    net, rou = d / f'inD_{k}.net.xml', d / f'inD_{k}.rou.xml'
    if not net.exists():
        raise SumoError(f'inD network {net} missing (../shared/realdata beside the checkout)')
    return net, rou
