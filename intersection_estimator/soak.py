"""``intersection-estimator soak``: a long drive through simulated intersections, fast.

Streams simulated traffic as *messages* (the node's input types, built with rosbags'
classes) through the node's pipeline (:class:`~.ingest.Ingest` ->
:class:`~.pipeline.OnlineEstimator` -> output messages), faster than real time, one
intersection after the other: after each scenario the ego drives through the center,
which makes the pipeline reset and start on the next one, as in a real drive. Reports the
resident memory per simulated minute (growth after warm-up) and the tick time.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass, field
import gc
import json
import math
import os
import sys
import time

import numpy as np

from . import params as P
from .bagio import BAG_T0, drive_through, scenario_messages, scenario_mount, typestore
from .ingest import Ingest, tick
from .pipeline import OnlineEstimator
from .roles import role_of_type
from .sim import simulate_scenario

__all__ = ['SoakReport', 'soak', 'rss_mb', 'register']


def rss_mb() -> float:
    """Resident set size of this process [MB] (Linux /proc)."""
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2**20


@dataclass
class SoakReport:
    """Figures of one soak run; ``rss_mb`` / ``tick_ms_*`` are per simulated minute."""

    minutes: float
    seed: int
    intersections: int = 0
    resets: int = 0
    messages: int = 0
    ticks: int = 0
    wall_s: float = 0.0
    rss_mb: list = field(default_factory=list)
    tick_ms_median: list = field(default_factory=list)
    tick_ms_p95: list = field(default_factory=list)
    dropped: dict = field(default_factory=dict)
    warmup_minutes: float = 0.0

    @property
    def growth_mb(self) -> float:
        """Memory growth after warm-up: max RSS after it minus RSS at its end."""
        w = min(len(self.rss_mb) - 1, max(0, int(math.ceil(self.warmup_minutes))))
        return float(max(self.rss_mb[w:]) - self.rss_mb[w]) if self.rss_mb else 0.0

    def lines(self) -> list[str]:
        speed = self.minutes * 60 / max(self.wall_s, 1e-9)
        return [f'soak: {self.minutes:g} simulated min ({self.intersections} intersections, {self.resets} resets, '
                f'{self.messages} messages, {self.ticks} ticks) in {self.wall_s:.1f} s wall ({speed:.1f}x real time), '
                f'seed {self.seed}',
                f'memory: {self.rss_mb[0]:.1f} MB after minute 1, {self.rss_mb[-1]:.1f} MB at the end, '
                f'growth after {self.warmup_minutes:g} min warm-up {self.growth_mb:.1f} MB',
                'tick ms median per minute: ' + ' '.join(f'{v:.1f}' for v in self.tick_ms_median),
                'tick ms p95 per minute:    ' + ' '.join(f'{v:.1f}' for v in self.tick_ms_p95),
                'dropped: ' + (', '.join(f'{k} {v}' for k, v in sorted(self.dropped.items())) or 'nothing')]


def soak(minutes: float, *, seed: int = 0, sensors=('tracked', 'raw'), topology_samples: int = 1000,
         lane_samples: int = 2000, period: float = 0.5, warmup_minutes: float | None = None,
         progress: bool = True) -> SoakReport:
    """Run the pipeline over ``minutes`` of simulated driving; see the module docstring."""
    from msg_adapters.types import RosbagsTypes
    values = P.defaults()
    values.update(topology_samples=topology_samples, lane_samples=lane_samples, timer_period=period,
                  seed=seed, window_s=60.0, mount_frames=['radar'], mount_x=[0.0], mount_y=[0.0],
                  mount_yaw=[0.0])
    types = RosbagsTypes(typestore())
    ingest, est = Ingest(values, types), OnlineEstimator(P.pipeline_config(values), seed=seed)
    report = SoakReport(minutes, seed, warmup_minutes=(max(1.0, 0.1 * minutes) if warmup_minutes is None
                                                       else warmup_minutes))
    sim_t, next_tick, minute_ticks, t_wall = 0.0, None, [], time.perf_counter()
    bar = _bar(minutes, progress)
    while sim_t < minutes * 60:
        sc = simulate_scenario(seed + report.intersections)
        mount = _mount_values(values, sc)
        ingest.configure(mount)
        msgs = scenario_messages(sc, types, sensors=sensors, autoware=False, t0=BAG_T0 + sim_t)
        last_t = BAG_T0 + sim_t
        for stream in (msgs, drive_through(types, sc.ego, sc.gt.center, BAG_T0 + sim_t + sc.duration)):
            for t, topic, msg in stream:
                role = role_of_type(msg.__msgtype__)    # the one role table (.roles)
                if role is None:                         # /tf_static: the mount is configured
                    continue
                ingest.handle(role, msg, est)
                report.messages += 1
                last_t = t
                next_tick = t + period if next_tick is None else next_tick
                while t >= next_tick:
                    before = est.result.topology_samples
                    t0 = time.perf_counter()
                    r = tick(ingest, est, wall_budget=False)
                    minute_ticks.append((time.perf_counter() - t0) * 1e3)
                    report.resets += int(r is not None and r.topology_samples < before)
                    report.ticks += 1
                    next_tick += period
                    if (next_tick - BAG_T0) // 60 > len(report.rss_mb):
                        _minute(report, minute_ticks, bar)
                        minute_ticks = []
        report.intersections += 1
        sim_t = last_t - BAG_T0 + 1.0
    if minute_ticks or not report.rss_mb:
        _minute(report, minute_ticks, bar)
    report.wall_s = time.perf_counter() - t_wall
    report.dropped = dict(ingest.dropped)
    if bar is not None:
        bar.close()
    return report


def _mount_values(values: dict, sc) -> dict:
    mx, my, myaw = scenario_mount(sc)
    return dict(values, mount_x=[mx], mount_y=[my], mount_yaw=[myaw])


def _minute(report: SoakReport, ticks: list, bar) -> None:
    gc.collect()
    report.rss_mb.append(round(rss_mb(), 2))
    t = np.asarray(ticks if ticks else [0.0])
    report.tick_ms_median.append(round(float(np.median(t)), 2))
    report.tick_ms_p95.append(round(float(np.percentile(t, 95)), 2))
    if bar is not None:
        bar.update(1)
        bar.set_postfix(rss_mb=report.rss_mb[-1])


def _bar(minutes: float, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=int(math.ceil(minutes)), unit='sim-min', desc='soak', file=sys.stderr)


def register(sub) -> None:
    p = sub.add_parser('soak', help='long simulated drive through the node pipeline: memory and tick time',
                       description=__doc__)
    p.add_argument('--minutes', type=float, default=60.0, help='simulated minutes (default 60)')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--sensors', default='tracked,raw', help='comma list of tracked, raw, heading')
    p.add_argument('--topology-samples', type=int, default=1000, help='per tick (default 1000)')
    p.add_argument('--lane-samples', type=int, default=2000, help='per tick (default 2000)')
    p.add_argument('--period', type=float, default=0.5, help='tick period in simulated seconds')
    p.add_argument('--json', help='write the report as JSON here')
    p.add_argument('--quiet', action='store_true')
    p.set_defaults(func=_main)


def _main(args) -> int:
    sensors = tuple(s for s in args.sensors.split(',') if s)
    bad = [s for s in sensors if s not in ('tracked', 'raw', 'heading')]
    if bad or args.minutes <= 0 or args.period <= 0:
        print(f'soak: bad arguments: sensors {bad}, minutes {args.minutes}, period {args.period}', file=sys.stderr)
        return 2
    r = soak(args.minutes, seed=args.seed, sensors=sensors, topology_samples=args.topology_samples,
             lane_samples=args.lane_samples, period=args.period, progress=not args.quiet)
    print('\n'.join(r.lines()))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(dict(asdict(r), growth_mb=r.growth_mb), f, indent=1)
    return 0
