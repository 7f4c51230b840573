"""What a replay tells its user: the summary, the warnings, why nothing was estimated.

ROS-free and I/O-free apart from the warning callback; :mod:`.replay` fills it in.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

__all__ = ['EXIT_OK', 'EXIT_UNUSABLE', 'EXIT_DAMAGED', 'EXIT_NO_INTERSECTION', 'Intersection',
           'ReplaySummary', 'WarningLog', 'why_no_intersection']

#: Exit codes of ``replay`` / ``demo`` (also in ``--help``).
EXIT_OK, EXIT_UNUSABLE, EXIT_DAMAGED, EXIT_NO_INTERSECTION = 0, 1, 2, 3

#: Why Ingest dropped input, in words (the keys are its drop reasons).
REASON_TEXT = {
    'no_ego_pose': 'no ego pose for their stamps (odometry missing, or not covering them)',
    'unknown_frame': 'frame_id neither the fixed frame nor a sensor frame with a known mount '
                     '(mount_frames / /tf_static)',
    'frame_mismatch': 'odometry in another frame than fixed_frame',
    'too_large': 'more points than max_observations in one message',
    'no_doppler': 'PointCloud2 without a Doppler field (doppler_field)',
    'stamp_jump': 'stamps far from the time base',
    'non_finite': 'non-finite coordinates or stamps',
    'malformed': 'malformed messages',
    'out_of_range': 'coordinates beyond any metric map frame',
}


@dataclass
class Intersection:
    """One intersection of a drive: its final estimate, the observations it rests on,
    why it ended ('ego_passed', 'time_base_reset', 'end_of_input'), when (stamp [s]) and
    where the ego was then ((x, y, yaw) in the fixed frame, None without odometry)."""

    result: object
    window: object
    ended: str
    t_end: float | None
    ego: tuple | None = None


def why_no_intersection(received: dict, dropped: dict, detections: int, messages: int) -> str:
    """One line: why a run estimated no intersection, from Ingest's counts."""
    inputs = sum(v for k, v in received.items() if k != 'odometry_topic')
    if messages == 0 or inputs == 0:
        return 'no input message (radar, objects, detections) was read'
    drops = sorted(((v, k) for k, v in dropped.items() if v), reverse=True)
    if detections == 0 and drops:
        top = drops[0][1]
        counts = ', '.join(f'{k} {v}' for v, k in drops)
        return (f'every input message was dropped (of {inputs}: {counts}); mostly '
                f'{REASON_TEXT.get(top, top)}')
    if detections == 0:
        return f'the {inputs} input message(s) held no detections (empty)'
    extra = f'; dropped: {", ".join(f"{k} {v}" for v, k in drops)}' if drops else ''
    return f'{detections} detection(s) from {inputs} message(s) were too few for an estimate{extra}'


class WarningLog:
    """The ingest warnings the node would log, at most one per reason per ``period_s`` of
    *bag* time (so the output does not depend on machine speed), the rest counted; and
    notes on the input. Every line printed is kept in :attr:`lines`."""

    def __init__(self, sink=None, period_s: float = 5.0):
        self.sink, self.period_s = sink, period_s
        self.lines: list[str] = []
        self.infos: list[str] = []
        self._last: dict[str, float] = {}
        self._suppressed = Counter()

    def note(self, text: str) -> None:
        """A line for the user now (stderr in the CLI)."""
        self.lines.append(text)
        if self.sink is not None:
            self.sink(text)

    def info(self, text: str) -> None:
        """A line for the summary only (normal situations worth knowing)."""
        self.infos.append(text)

    def emit(self, warnings, t: float | None) -> None:
        """``warnings``: (reason, text) from ``Ingest.pop_warnings``; ``t``: bag time [s]
        (None: the end of the input, always printed)."""
        for reason, text in warnings:
            last = self._last.get(reason)
            if t is not None and last is not None and t - last < self.period_s:
                self._suppressed[reason] += 1
                continue
            n = self._suppressed.pop(reason, 0)
            self._last[reason] = t if t is not None else float('inf')
            self.note(f'warning: {text}' + (f' ({n} more since the last report)' if n else ''))


@dataclass
class ReplaySummary:
    """What a replay did (printed by the CLI, returned to callers and tests).

    ``result``: the last intersection's estimate (or the last, empty, result when there was
    none); ``intersections``: every :class:`Intersection` of the drive, in order.
    """

    messages: int
    ticks: int
    result: object
    files: dict
    dropped: dict
    wall_s: float
    truncated: str = ''
    intersections: list = field(default_factory=list)
    received: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    infos: list = field(default_factory=list)
    idle_ticks: int = 0
    why: str = ''

    @property
    def results(self) -> list:
        """The estimate of each intersection of the drive."""
        return [i.result for i in self.intersections]

    @property
    def exit_code(self) -> int:
        if not self.intersections:
            return EXIT_NO_INTERSECTION
        return EXIT_DAMAGED if self.truncated else EXIT_OK

    def lines(self) -> list[str]:
        idle = f' (+{self.idle_ticks} idle ticks written once)' if self.idle_ticks else ''
        out = [f'replayed {self.messages} messages, {self.ticks} ticks{idle} in {self.wall_s:.2f} s']
        if self.truncated:
            out.append(f'WARNING: bag truncated ({self.truncated}); estimate uses what could be read')
        if not self.intersections:
            out.append(f'no intersection estimated: {self.why}')
        for k, item in enumerate(self.intersections):
            out += _intersection_lines(k, item, len(self.intersections))
        if self.received:
            out.append('received: ' + ', '.join(f'{k} {v}' for k, v in sorted(self.received.items())))
        out += [f'note: {text}' for text in self.infos]
        out.append('dropped: ' + (', '.join(f'{k} {v}' for k, v in sorted(self.dropped.items())) or 'nothing'))
        out += [f'wrote {p}' for p in self.files.values()]
        return out

    def to_json(self) -> dict:
        return {'messages': self.messages, 'ticks': self.ticks, 'idle_ticks': self.idle_ticks,
                'files': self.files, 'received': self.received, 'dropped': self.dropped,
                'wall_s': self.wall_s, 'truncated': self.truncated, 'why': self.why,
                'exit_code': self.exit_code, 'notes': self.notes, 'infos': self.infos,
                'intersections': [_intersection_json(i) for i in self.intersections]}


def _intersection_lines(k: int, item: Intersection, n: int) -> list[str]:
    r, I = item.result, item.result.intersection
    head = f'intersection {k:02d} ({_ended(item)}): ' if n > 1 else ''
    out = [f'{head}center ({I.center[0]:.2f}, {I.center[1]:.2f}) m, {len(I.arms)} arms, '
           f'state {r.state}, {r.topology_samples} topology + {r.lane_samples} lane samples']
    for i, a in enumerate(I.arms):
        out.append(f'  arm {i}: {a.angle * 57.29577951308232:7.1f} deg, gap {a.gap:.1f} m, '
                   f'lanes in/out {a.lanes_in}/{a.lanes_out}, width {a.lane_width:.2f} m')
    kinds = {k: sum(1 for ll in r.lanelets if ll.kind == k) for k in ('entering', 'leaving', 'connector')}
    out.append('lanelets: ' + ', '.join(f'{v} {k}' for k, v in kinds.items()))
    return out


def _ended(item: Intersection) -> str:
    words = {'ego_passed': 'ego passed', 'time_base_reset': 'time base moved', 'end_of_input': 'end of input'}
    at = f' at {item.t_end:.1f} s' if item.t_end is not None and item.ended != 'end_of_input' else ''
    return words.get(item.ended, item.ended) + at


def _intersection_json(item: Intersection) -> dict:
    r, I = item.result, item.result.intersection
    return {'center': [float(I.center[0]), float(I.center[1])], 'arms': len(I.arms), 'state': r.state,
            'ended': item.ended, 't_end': item.t_end, 'lanelets': len(r.lanelets)}
