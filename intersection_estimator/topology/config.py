"""Configuration of the topology step (paper §II): :class:`TopologyConfig`, the
preprocessing subset :class:`PreprocessConfig` derived from it, and :class:`Tables`, the
prior / proposal / kernel tables a config implies (computed once per estimator).

Every parameter has one entry in :data:`RANGES`: its allowed interval (``[`` / ``]``
closed, ``(`` / ``)`` open; a bound may name another parameter) and what it means, with
its unit. ``validate()`` checks them in field order, then the rules that involve several
parameters. What was tried and measured for the defaults: ``docs/tuning.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, make_dataclass, replace
import math

import numpy as np

from ..ranges import check_labels, check_range
from .prior import ARM_COUNT_PRIOR, LANE_COUNT_PRIOR, arm_log_const, count_log_table
from .arm_offset import offset_log_const
from .refit import log_floor_table
from .state import (MAXA, NPARAM, P_BEND_MAX, P_BEND_S_MAX, P_BEND_S_MIN, P_BEND_S_STEP,
                    P_BEND_SCALE, P_BEND_STEP, P_C_ARM, P_C_GAP, P_C_LANE, P_C_OFFSET,
                    P_C_ROT, P_C_SHIFT, P_C_WIDTH, P_OFF_LAPLACE,
                    P_D2_CUT, P_OFF_MAX, P_OFF_SIGMA, P_OFF_STEP,
                    P_FINE_P, P_FINE_SCALE, P_FLOOR, P_FOCUS, P_FOCUS_P, P_GAP_MAX,
                    P_GAP_STEP, P_LANE_NORM, P_LANE_SUM, P_MAX_ARMS, P_MAX_LANES, P_MIN_ARMS,
                    P_MIN_LANES, P_MIN_SEP, P_ROT, P_SAMPLE_W, P_SHIFT, P_SPLIT_SPAN,
                    P_TRAFFIC, P_W_DEFAULT, P_W_MAX, P_W_MIN, P_W_STEP)

__all__ = ['TopologyConfig', 'PreprocessConfig', 'PREPROCESS_FIELDS', 'RANGES', 'Tables']

# name -> (allowed interval, meaning [unit]); see the module docstring
RANGES = {
    # move probabilities (Algorithm 1), normalised to sum 1
    'p_rotate': ('[0, 1]', 'probability of the rotate-arm move'),
    'p_shift': ('[0, 1]', 'probability of the shift-center move'),
    'p_gap': ('[0, 1]', 'probability of the change-gap move'),
    'p_arm': ('[0, 1]', 'probability of the add/remove-arm move'),
    'p_lane': ('[0, 1]', 'probability of the add/remove-lane move'),
    'p_width': ('[0, 1]', 'probability of the lane-width move (beyond the paper; 0: width fixed '
                'at lane_width)'),
    'p_offset': ('[0, 1]', 'probability of the arm-axis offset move (beyond the paper, '
                 'arm_offset.py; only when arm_offset_max > 0)'),
    'p_bend': ('[0, 1]', 'probability of the arm-bend move (beyond the paper, arm_bend.py; only '
               'when arm_bend_max_deg > 0)'),
    # move ranges (Algorithm 1)
    'rotate_max_deg': ('(0, 180]', 'largest rotation of an arm [deg]'),
    'shift_max': ('(0, 100]', 'largest shift of the center [m]'),
    'gap_step': ('(0, 20]', 'largest change of a median gap [m]'),
    'width_step': ('(0, 2]', 'largest change of a lane width [m]'),
    'offset_step': ('(0, 10]', 'largest change of an arm-axis offset [m]'),
    'bend_step_deg': ('(0, 90]', 'largest change of an arm bend [deg]'),
    'bend_at_step': ('(0, 100]', 'largest change of the place of an arm bend [m]'),
    'fine_step_prob': ('[0, 1]', 'probability that a continuous move uses the fine range'),
    'fine_step_scale': ('(0, 1]', 'fine range as a share of the move range'),
    'split_span_deg': ('[0, 180]', "add-arm 'split': offset U[min_sep, min_sep + this] from an "
                       'arm [deg]'),
    # model bounds (§II-B)
    'min_sep_deg': ('[1, 120]', 'smallest angle between two arms [deg]'),
    'min_arms': (f'[1, {MAXA}]', 'fewest arms of an intersection'),
    'max_arms': (f'[min_arms, {MAXA}]', 'most arms of an intersection'),
    'min_lanes': ('[1, max_lanes]', 'fewest lanes per driving direction (no one-way roads)'),
    'max_lanes': ('[min_lanes, inf)', 'most lanes per driving direction'),
    'gap_max': ('(0, 30]', 'widest median gap [m]'),
    'gap_max_tracked': ('[0, 30]', 'widest median gap for windows with tracked objects, where it '
                        'also spans the lanes of a direction no vehicle drove (0: gap_max) [m]'),
    'arm_offset_max': ('[0, 30]', 'largest sideways offset of an arm axis from the center '
                       '(0: arms are rays from the center, paper §II-B) [m]'),
    'arm_offset_sigma': ('(0, 30]', 'sigma (normal) or scale (Laplace) of the prior of an arm-axis '
                         'offset [m]'),
    'arm_offset_tracks_only': (None, 'the arm-axis offset and bend only for windows with tracked objects '
                               '(radar / heading voxels are too coarse to place it)'),
    'arm_offset_prior': (None, "'normal' or 'laplace': the prior of an arm-axis offset "
                         '(arm_offset.py)'),
    'arm_bend_max_deg': ('[0, 90]', 'largest bend of an arm axis (0: straight arms, paper §II-B; '
                         'arm_bend.py) [deg]'),
    'arm_bend_scale_deg': ('(0, 90]', 'scale of the Laplace prior of an arm bend [deg]'),
    'arm_bend_at_min': ('[0, arm_bend_at_max)', 'nearest place of an arm bend along its axis [m]'),
    'arm_bend_at_max': ('(arm_bend_at_min, 500]', 'farthest place of an arm bend along its axis '
                        '[m]'),
    'lane_width': ('[lane_width_min, lane_width_max]', 'lane width of a new arm, and of every '
                   'arm when p_width = 0 [m]'),
    'lane_width_min': ('[1, lane_width_max)', 'narrowest lane [m]'),
    'lane_width_max': ('(lane_width_min, 6]', 'widest lane [m]'),
    'traffic_side': ('[-1, 1]', '+1 right-hand traffic, -1 left-hand'),
    # prior (§II-C1, prior.py)
    'arm_count_prior': (None, f'P(|A| = i), i = 0..{MAXA}'),
    'lane_count_prior': (None, 'P(lanes per direction = i), i = 0..len-1'),
    # likelihood (§II-C2)
    'sigma_track': ('[0.01, 20]', 'lateral sigma of a trajectory part\'s mean point [m]'),
    'sigma_track_weak': ('[0.01, 20]', 'lateral sigma of a trajectory part of a weak_labels road '
                         'user (cyclist, pedestrian: not at a lane center) [m]'),
    'weak_labels': (None, 'Autoware classification labels whose tracks count as traffic of an '
                    'arm but not of a lane of their own (sigma_track_weak)'),
    'sigma_point': ('[0.01, 20]', 'lateral sigma of a detection (raw / heading voxel) [m]'),
    'sigma_angle_deg': ('[0.1, 90]', 'heading sigma of a trajectory part / detection [deg]'),
    'pca_radius': ('[1, 50]', 'initial center: radius of the local PCA of radar voxels [m]'),
    'min_arm_support': ('[0, inf)', 'reported arms explain at least this many vehicle passages'),
    'clutter_floor': ('(0, 1)', 'uniform outlier density relative to the peak density'),
    'cut_sigma2': ('[1, 700]', 'densities below exp(-cut_sigma2) count as 0'),
    'lane_sum': (None, 'sum the density over lanes (paper eq.) instead of the closest lane'),
    'lane_norm': ('[0, 2]', 'density divided by (lanes of that arm and direction) ** this'),
    # preprocessing (§II-A)
    'voxel_size': ('[0.05, 50]', 'edge of square voxels (rows before arms are known) [m]'),
    'voxel_length': ('[0, 100]', 'arm-aligned voxels: length along the arm (0: square) [m]'),
    'voxel_width': ('[0.05, 20]', 'arm-aligned voxels: width across the arm [m]'),
    'straight_run': (None, 'drop arm-aligned voxels without occupied neighbours along the arm'),
    'voxel_merge': ('[1, 20]', 'radar: merge this many along-arm voxels'),
    'heading_voxel_merge': ('[1, 20]', 'lidar / camera rows: merge this many along-arm voxels'),
    'heading_sectors': ('[1, 64]', 'square heading voxels: sectors of 360/n deg'),
    'passage_gap': ('[0, 60]', 'stamps farther apart are another vehicle passage (0: weights '
                    'in detections) [s]'),
    'weight_power': ('[0, 2]', 'voxel weight = scale * passages ** power'),
    'weight_scale': ('(0, 100]', 'voxel weight = scale * passages ** power'),
    'min_doppler': ('[0, 50]', 'radar rows with smaller |Doppler| are static [m/s]'),
    'min_rcs': ('[-inf, inf]', 'radar rows with a smaller RCS are clutter (NaN kept) [dBsm]'),
    'min_rcs_static': ('[-inf, inf]', 'slow (crossing) radar rows kept from this RCS [dBsm]'),
    'keep_unknown_direction': (None, 'keep radar rows of unknown driving direction (d = 0)'),
    'min_radial_cos': ('[0, 1)', 'radar rows with smaller |<radial, line of sight>| are dropped'),
    'min_part_points': ('[1, 1000]', 'trajectory parts with fewer points are dropped'),
    'min_part_length': ('[0, 100]', 'trajectory parts with a shorter extent are dropped [m]'),
    'min_track_speed': ('[0, 50]', 'tracks never faster than this are static (false) [m/s]'),
    'standing_weight': ('[0, 100]', 'weight of a vehicle that stood through the recording (a '
                        'queue): evidence of its arm, sigma_track_weak across (topology/standing.py; '
                        '0: standing vehicles are not observations)'),
    'standing_min_s': ('[0, 3600]', 'a standing track is a vehicle when it lived this long [s]'),
    'standing_queue': ('[1, 100]', 'a standing vehicle counts when it stands in a queue of this '
                       'many, one behind the other (1: alone too)'),
    'trim_turn_deg': ('[0, 90]', 'keep the straight run of a trajectory part (0: whole part, '
                      'paper) [deg]'),
    'max_center_dist': ('(min_center_dist, inf]', 'radar / heading observations farther from the '
                        'center are dropped (arms are straight rays, §II-B; real approaches curve) [m]'),
    'trim_longest': (None, 'trajectory parts: keep their longest straight run, not the first from '
                     'the far end (beyond the paper; preprocess.straight_run)'),
    'track_radius': ('(min_center_dist, inf]', 'trajectory rows farther from the center do not enter '
                     'the trajectory parts (their mean point and direction, §II-A) [m]'),
    'part_outside': ('[0, 100]', 'trajectory parts: only their rows beyond this distance from the '
                     'center, from the far end, and it replaces min_center_dist for them (0: the '
                     'whole part, paper §II-A; preprocess.split_tracks) [m]'),
    'part_piece_m': ('[0, 200]', 'trajectory parts: one mean per this many metres driven, each '
                     'weighted by its share of the part (0: one mean per part, paper §II-A) [m]'),
    'bend_min_deg': ('[0, 90]', 'straighten an arm direction whose traffic turns by at least this '
                     'along the arm before the parts are reduced (0: off, straight arms, paper '
                     '§II-B; bend.py) [deg]'),
    'bend_bin': ('[1, 30]', 'bin length along the arm of the bend profile (bend.py) [m]'),
    'min_center_dist': ('[0, 100]', 'observations closer to the center are dropped (vehicles '
                        'turn inside the box; lanes are straight rays, §II-B) [m]'),
    'arm_reach': ('[1, 100]', 'rows farther from every arm axis are voxelised along rays '
                  '(arm not found yet) [m]'),
    'recenter_threshold': ('(0, inf)', 're-preprocess when the best center moved more [m]'),
    'recenter_window': ('[0, inf)', '... checked during this many samples after new data'),
    # annealing (mcmc.py)
    't_start': ('(0, 1e4]', 'temperature at sample 0'),
    't_end': ('(0, t_start]', 'temperature from anneal_samples on'),
    'anneal_samples': ('[1, inf)', 'length of the geometric schedule [samples]'),
    'chains': ('[1, 16]', 'independent chains (own RNG streams, one observation set)'),
    'chains_tracked': ('[1, 16]', '... when the data hold trajectories'),
    'init_peak_frac': ('(0, 1]', 'init: direction-histogram peaks above this share of the top'),
    'refit_every': ('[0, inf)', 'refit every arm every this many samples (0: never) (refit.py)'),
    'refit_sweeps': ('[0, 10]', 'sweeps of each refit over the arms'),
    'polish_samples': ('[0, inf)', 'first samples of a new chain: continuous moves only'),
    'reheat_fraction': ('[0, 1]', 'on new data: back to this share of the schedule'),
    # descent (descent.py)
    'descent_rounds': ('[0, 10]', 'rounds of the greedy descent at the end of the schedule '
                       '(0: off)'),
    'descent_samples': ('[1, 1e6]', 'continuous moves per descent candidate'),
    'descent_temp': ('(0, 1]', 'temperature of those moves'),
    'descent_screen': ('[0, inf)', 'lane candidates this many nats behind the best state get '
                       'no moves [nats]'),
    'descent_prune': ('[0, inf)', 'a run stops once this many nats x (share of moves left)^2 '
                      'behind [nats]'),
    'descent_focus': ('[0, 1]', 'share of a lane candidate\'s arm moves on its changed arm'),
    'descent_top': ('[0, 1000]', 'only the best this many lane candidates get moves (0: all)'),
    'descent_add_support': ('[0, inf)', 'the descent also tries an arm where trajectory parts of '
                            'this many vehicle passages are explained by no arm (0: off; '
                            'topology/unexplained.py)'),
    'radar_tracks_add_support': ('[0, inf)', 'descent_add_support for a window whose tracks all '
                                 'come from the radar tracker (0: off; their breaks leave parts '
                                 'no arm explains)'),
    'radar_tracks_min_part_length': ('[0, 100]', 'min_part_length for a window whose tracks all '
                                     'come from the radar tracker [m]'),
    # reported estimate
    'side_by_side_overlap': ('[0, 1000]', 'an arm has at least the lanes that trajectory parts '
                             'overlapping by this many metres show side by side (0: off; '
                             'topology/side_by_side.py) [m]'),
    'side_by_side_cap': ('[0, 1000]', 'with at least this many trajectory parts compared side by '
                         'side, an arm direction has at most one lane beyond those they show '
                         '(0: no cap; topology/side_by_side.py)'),
    'side_by_side_single': (None, 'an arm direction in which no two trajectory parts overlap '
                            'side by side keeps one lane (topology/side_by_side.py)'),
    'side_by_side_width': (None, 'the lanes shown side by side are read with the arm\'s width '
                           'capped at lane_width (topology/side_by_side.py)'),
    'side_by_side_reach': ('[0, 1000]', 'entering lanes side by side are also read from '
                           'trajectory rows up to this far beyond track_radius, as a window of '
                           'their own (topology/side_by_side.py) [m]'),
    'side_by_side_occupied': (None, 'a lane count above the lanes shown side by side drops '
                              'by one lane when a lane holds no trajectory part\'s median '
                              'position (topology/side_by_side.py)'),
    'side_by_side_queues': ('[0, 100]', 'queues of at least this many vehicles standing on an '
                            'arm\'s entering side count as trajectory parts of their lanes side '
                            'by side (0: off; topology/side_by_side.py)'),
    'weak_arm_nats': ('[0, 100]', 'windows with trajectories: an arm is added where unexplained '
                      'trajectory parts are and the state with it is at most this many nats '
                      'below the state without (0: off; topology/weak_arms.py) [nats]'),
    'weak_arm_support': ('(0, inf)', '... and the added arm explains at least this many vehicle '
                         'passages, and as many tracks drive it across the line weak_arm_box '
                         'out on its axis'),
    'weak_arm_box': ('(part_outside, inf)', 'the tracks of an added arm drive it across the line this far '
                     'out on its axis: the road leads to the junction [m]'),
    'empty_arm_drop': (None, 'windows with tracked objects (not the radar tracker\'s): an arm '
                       'that, its lane counts set, explains fewer than weak_arm_support passages '
                       'and along which as few tracks drove between part_outside and '
                       'weak_arm_box is left out (topology/support.py)'),
    'empty_arm_reach': ('[0, 10]', '... tracks within this many lane widths beside the arm\'s '
                        'lanes drove along it [lane widths]'),
    # anytime API
    'chunk': ('[1, 1e7]', 'samples per compiled call (anytime granularity)'),
    'converge_window': ('[1, inf)', "state 'CONVERGED' after this many samples without gain"),
    'converge_tol': ('[0, inf)', '... of more than this [nats]'),
}

def _check_range(cfg, name: str) -> None:
    """Raise ValueError unless ``cfg.<name>`` lies in its :data:`RANGES` interval."""
    check_range(cfg, name, *RANGES[name])


def _need(cfg, name: str, ok: bool, rule: str) -> None:
    if not ok:
        raise ValueError(f'{type(cfg).__name__}.{name}={getattr(cfg, name)!r}: needs {rule}')


@dataclass(frozen=True)
class TopologyConfig:
    """All parameters of the topology step (meaning and unit of each: :data:`RANGES`);
    defaults follow the paper where it gives one."""

    # move probabilities (Algorithm 1)
    p_rotate: float = 0.40
    p_shift: float = 0.20
    p_gap: float = 0.10
    p_arm: float = 0.15
    p_lane: float = 0.15
    p_width: float = 0.10
    p_offset: float = 0.10
    p_bend: float = 0.10
    # move ranges (Algorithm 1)
    rotate_max_deg: float = 6.0
    shift_max: float = 6.0
    gap_step: float = 1.8
    width_step: float = 0.25
    offset_step: float = 1.5
    bend_step_deg: float = 6.0
    bend_at_step: float = 10.0
    fine_step_prob: float = 0.5
    fine_step_scale: float = 0.1
    split_span_deg: float = 60.0
    # model bounds
    min_sep_deg: float = 30.0
    min_arms: int = 2
    max_arms: int = 6
    min_lanes: int = 1
    max_lanes: int = 6
    gap_max: float = 4.0
    gap_max_tracked: float = 8.0
    arm_offset_max: float = 10.0
    arm_offset_sigma: float = 1.0
    arm_offset_prior: str = 'laplace'
    arm_bend_max_deg: float = 0.0
    arm_bend_scale_deg: float = 10.0
    arm_bend_at_min: float = 10.0
    arm_bend_at_max: float = 60.0
    arm_offset_tracks_only: bool = True
    lane_width: float = 3.5
    lane_width_min: float = 2.75
    lane_width_max: float = 4.0
    traffic_side: int = 1
    # prior
    arm_count_prior: tuple = ARM_COUNT_PRIOR
    lane_count_prior: tuple = LANE_COUNT_PRIOR
    # likelihood
    sigma_track: float = 0.8
    sigma_track_weak: float = 4.0
    weak_labels: tuple = (6, 7)
    sigma_point: float = 1.2
    sigma_angle_deg: float = 5.0
    pca_radius: float = 8.0
    min_arm_support: float = 1.5
    clutter_floor: float = 0.01
    cut_sigma2: float = 30.0
    lane_sum: bool = False
    lane_norm: float = 0.5
    # preprocessing
    voxel_size: float = 3.0
    voxel_length: float = 10.0
    voxel_width: float = 1.0
    straight_run: bool = True
    voxel_merge: int = 3
    heading_voxel_merge: int = 2
    heading_sectors: int = 8
    passage_gap: float = 1.0
    weight_power: float = 1.0
    weight_scale: float = 0.3
    min_doppler: float = 0.5
    min_rcs: float = 0.0
    min_rcs_static: float = 5.0
    keep_unknown_direction: bool = True
    min_radial_cos: float = 0.25
    min_part_points: int = 3
    min_part_length: float = 5.0
    min_track_speed: float = 3.0
    standing_weight: float = 1.0
    standing_min_s: float = 2.0      # AV2 tracks a passed queue 2-3 s (docs/real_junctions.md)
    standing_queue: int = 2
    trim_turn_deg: float = 15.0
    min_center_dist: float = 20.0
    part_outside: float = 12.0
    part_piece_m: float = 0.0
    bend_min_deg: float = 0.0
    bend_bin: float = 5.0
    max_center_dist: float = math.inf
    track_radius: float = 75.0
    trim_longest: bool = True
    arm_reach: float = 18.0
    recenter_threshold: float = 2.0
    recenter_window: int = 2500
    # annealing
    t_start: float = 1.0
    t_end: float = 0.2
    anneal_samples: int = 5000
    chains: int = 1
    chains_tracked: int = 2
    init_peak_frac: float = 0.12
    refit_every: int = 1000
    refit_sweeps: int = 1
    polish_samples: int = 1000
    reheat_fraction: float = 0.3
    # descent
    descent_rounds: int = 2
    descent_samples: int = 250
    descent_temp: float = 1e-3
    descent_screen: float = 4.5
    descent_prune: float = 3.0
    descent_focus: float = 0.8
    descent_top: int = 0
    descent_add_support: float = 1.5
    radar_tracks_add_support: float = 3.0   # descent_add_support on radar-tracker windows
    radar_tracks_min_part_length: float = 3.0   # docs/real_junctions.md, "Stop 56"
    # reported estimate
    side_by_side_overlap: float = 8.0
    side_by_side_cap: int = 2
    side_by_side_single: bool = True
    side_by_side_width: bool = True      # docs/real_junctions.md, "Stop 48"
    side_by_side_reach: float = 50.0     # docs/real_junctions.md, "Stop 49"
    side_by_side_occupied: bool = True   # docs/real_junctions.md, "Stop 50"
    side_by_side_queues: int = 3         # docs/real_junctions.md, "Stop 51"
    weak_arm_nats: float = 1.0
    weak_arm_support: float = 1.0
    weak_arm_box: float = 25.0
    empty_arm_drop: bool = True         # docs/real_junctions.md, "Stop 50"
    empty_arm_reach: float = 1.0         # docs/real_junctions.md, "Stop 56"
    # anytime API
    chunk: int = 500
    converge_window: int = 2000
    converge_tol: float = 0.5

    def validate(self) -> 'TopologyConfig':
        """Raise ValueError naming the first parameter outside its allowed range."""
        for f in fields(self):
            _check_range(self, f.name)
        _need(self, 'p_rotate', sum(getattr(self, n) for n in _MOVE_P) > 0,
              'a positive sum of the move probabilities')
        _need(self, 'max_arms', self.max_arms * self.min_sep_deg <= 360,
              'max_arms * min_sep_deg <= 360')
        _need(self, 'max_lanes', self.max_lanes <= len(self.lane_count_prior) - 1,
              'max_lanes <= len(lane_count_prior) - 1')
        _need(self, 'traffic_side', self.traffic_side in (1, -1), 'one of 1, -1')
        _need(self, 'arm_offset_prior', self.arm_offset_prior in ('normal', 'laplace'),
              "one of 'normal', 'laplace'")
        _need(self, 'arm_count_prior', len(self.arm_count_prior) == MAXA + 1
              and min(self.arm_count_prior) >= 0
              and sum(self.arm_count_prior[self.min_arms:self.max_arms + 1]) > 0,
              f'{MAXA + 1} non-negative probabilities with mass on [min_arms, max_arms]')
        _need(self, 'lane_count_prior', min(self.lane_count_prior) >= 0
              and sum(self.lane_count_prior[self.min_lanes:self.max_lanes + 1]) > 0,
              'non-negative probabilities with mass on [min_lanes, max_lanes]')
        _check_flags(self)
        check_labels(self, 'weak_labels')
        return self

    def for_tracks(self) -> 'TopologyConfig':
        """The model for windows with tracked objects: ``gap_max_tracked`` as the gap bound."""
        if self.gap_max_tracked <= 0.0 or self.gap_max_tracked == self.gap_max:
            return self
        return replace(self, gap_max=self.gap_max_tracked)

    def for_voxels(self) -> 'TopologyConfig':
        """The model for windows without tracked objects: no axis offset or bend when
        ``arm_offset_tracks_only``."""
        if (self.offset_on or self.bend_on) and self.arm_offset_tracks_only:
            return replace(self, arm_offset_max=0.0, arm_bend_max_deg=0.0)
        return self

    @property
    def offset_on(self) -> bool:
        """Do arms carry an axis offset (:mod:`.arm_offset`)?"""
        return self.arm_offset_max > 0 and self.p_offset > 0

    @property
    def bend_on(self) -> bool:
        """Do arms carry a bend (:mod:`.arm_bend`)?"""
        return self.arm_bend_max_deg > 0 and self.p_bend > 0

    @property
    def sample_width(self) -> bool:
        """Is the lane width sampled (width move on), or fixed at ``lane_width``?"""
        return self.p_width > 0

    def preprocess_config(self) -> 'PreprocessConfig':
        """The preprocessing parameters of this config."""
        return PreprocessConfig(**{n: getattr(self, n) for n in PREPROCESS_FIELDS})

    def kernel_params(self, continuous_only: bool = False) -> np.ndarray:
        """The kernel parameter vector ``P`` (:mod:`.state`); ``continuous_only``: without
        the dimension moves (add/remove arm / lane)."""
        P = np.zeros(NPARAM)
        p = np.array([getattr(self, n) for n in _MOVE_P])
        if continuous_only:
            p[3:5] = 0.0
        if not self.offset_on:
            p[6] = 0.0
        if not self.bend_on:
            p[7] = 0.0
        cum = np.cumsum(p / p.sum())
        P[P_MIN_SEP] = math.radians(self.min_sep_deg)
        P[P_MIN_ARMS], P[P_MAX_ARMS] = self.min_arms, self.max_arms
        P[P_MIN_LANES], P[P_MAX_LANES] = self.min_lanes, self.max_lanes
        P[P_GAP_MAX] = self.gap_max
        P[P_W_MIN], P[P_W_MAX] = self.lane_width_min, self.lane_width_max
        P[P_ROT] = math.radians(self.rotate_max_deg)
        P[P_SHIFT] = self.shift_max
        P[P_GAP_STEP] = self.gap_step
        P[P_W_STEP] = self.width_step
        P[P_SPLIT_SPAN] = math.radians(self.split_span_deg)
        P[[P_C_ROT, P_C_SHIFT, P_C_GAP, P_C_ARM, P_C_LANE, P_C_WIDTH, P_C_OFFSET]] = cum[:7]
        # exactly 1 where the later moves are never picked (cumsum may round)
        if p[7] == 0.0:
            P[P_C_OFFSET] = 1.0
            if p[6] == 0.0:
                P[P_C_WIDTH] = 1.0
        P[P_OFF_MAX] = self.arm_offset_max if self.offset_on else 0.0
        P[P_OFF_STEP] = self.offset_step
        P[P_OFF_SIGMA] = self.arm_offset_sigma
        P[P_OFF_LAPLACE] = float(self.arm_offset_prior == 'laplace')
        P[P_BEND_MAX] = math.radians(self.arm_bend_max_deg) if self.bend_on else 0.0
        P[P_BEND_STEP] = math.radians(self.bend_step_deg)
        P[P_BEND_SCALE] = math.radians(self.arm_bend_scale_deg)
        P[P_BEND_S_MIN], P[P_BEND_S_MAX] = self.arm_bend_at_min, self.arm_bend_at_max
        P[P_BEND_S_STEP] = self.bend_at_step
        P[P_FLOOR] = self.clutter_floor
        P[P_TRAFFIC] = self.traffic_side
        P[P_D2_CUT] = self.cut_sigma2
        P[P_SAMPLE_W] = 1.0 if self.sample_width else 0.0
        P[P_W_DEFAULT] = self.lane_width
        P[P_LANE_NORM] = self.lane_norm
        P[P_LANE_SUM] = 1.0 if self.lane_sum else 0.0
        P[P_FOCUS], P[P_FOCUS_P] = 0.0, 0.0     # no focus arm (the descent sets one)
        P[P_FINE_P] = self.fine_step_prob
        P[P_FINE_SCALE] = self.fine_step_scale
        return P


_MOVE_P = ('p_rotate', 'p_shift', 'p_gap', 'p_arm', 'p_lane', 'p_width', 'p_offset', 'p_bend')
_FLAGS = ('lane_sum', 'straight_run', 'keep_unknown_direction', 'trim_longest',
          'arm_offset_tracks_only')


def _check_flags(cfg) -> None:
    for n in _FLAGS:
        if hasattr(cfg, n):
            _need(cfg, n, isinstance(getattr(cfg, n), (bool, np.bool_)), 'a bool')


#: The parameters preprocessing (preprocess.py, voxels.py, init.py) reads.
PREPROCESS_FIELDS = (
    'sigma_track', 'sigma_track_weak', 'weak_labels', 'sigma_point', 'sigma_angle_deg', 'pca_radius', 'voxel_size',
    'voxel_length', 'voxel_width', 'straight_run', 'voxel_merge', 'heading_voxel_merge',
    'heading_sectors', 'passage_gap', 'weight_power', 'weight_scale', 'min_doppler', 'min_rcs',
    'min_rcs_static', 'keep_unknown_direction', 'min_radial_cos', 'min_part_points',
    'min_part_length', 'min_track_speed', 'standing_weight', 'standing_min_s', 'standing_queue',
    'trim_turn_deg', 'min_center_dist', 'max_center_dist', 'track_radius', 'trim_longest',
    'arm_reach', 'part_outside', 'part_piece_m', 'bend_min_deg', 'bend_bin')


def _preprocess_validate(self) -> 'PreprocessConfig':
    """Raise ValueError naming the first parameter outside its allowed range."""
    for f in fields(self):
        _check_range(self, f.name)
    _check_flags(self)
    return self


#: The preprocessing subset of :class:`TopologyConfig`: same names, defaults, ranges.
PreprocessConfig = make_dataclass(
    'PreprocessConfig',
    [(f.name, f.type, field(default=f.default)) for f in fields(TopologyConfig)
     if f.name in PREPROCESS_FIELDS],
    frozen=True, namespace={'validate': _preprocess_validate, '__module__': __name__,
                            '__doc__': 'Parameters of the preprocessing (paper §II-A): the '
                            'subset PREPROCESS_FIELDS of TopologyConfig, same defaults.'})


class Tables:
    """Prior / proposal / kernel tables derived from a config (computed once): kernel
    parameters ``P`` (``P_polish``: continuous moves only), log count priors ``logPA``,
    ``logPn`` (and the lane-count proposal ``logqn``, ``cumqn``), the refit grids ``gaps``,
    ``widths``, the per-arm log density constant ``arm_const`` and the refit's
    :func:`.refit.log_floor_table`."""

    def __init__(self, cfg: TopologyConfig):
        self.P = cfg.kernel_params()
        self.P_polish = cfg.kernel_params(continuous_only=True)
        self.logPA = count_log_table(cfg.arm_count_prior, cfg.min_arms, cfg.max_arms, MAXA + 1)
        size = cfg.max_lanes + 1
        self.logPn = count_log_table(cfg.lane_count_prior, cfg.min_lanes, cfg.max_lanes, size)
        self.logqn = self.logPn.copy()
        self.cumqn = np.cumsum(np.exp(self.logqn))
        self.gaps = np.linspace(0.0, cfg.gap_max, int(round(cfg.gap_max / 0.5)) + 1)
        self.widths = (np.linspace(cfg.lane_width_min, cfg.lane_width_max, 6)
                       if cfg.sample_width else np.zeros(0))
        self.arm_const = arm_log_const(cfg.gap_max, cfg.lane_width_min, cfg.lane_width_max,
                                       cfg.sample_width)
        if cfg.offset_on:
            self.arm_const += offset_log_const(cfg.arm_offset_sigma, cfg.arm_offset_max,
                                               cfg.arm_offset_prior == 'laplace')
        #: the (bend, place) points of :func:`.refit.refit_bend`: every 2.5 deg x 5 m, then
        #: straight (0, 0) last; empty when the bend is off
        self.bend_grid = np.zeros((0, 2))
        if cfg.bend_on:
            mb = math.radians(cfg.arm_bend_max_deg)
            nb = int(math.ceil(cfg.arm_bend_max_deg / 2.5))
            ats = np.linspace(cfg.arm_bend_at_min, cfg.arm_bend_at_max, int(math.ceil(
                (cfg.arm_bend_at_max - cfg.arm_bend_at_min) / 5.0)) + 1)
            self.bend_grid = np.array([(b, at) for b in np.linspace(-mb, mb, 2 * nb + 1) if b != 0.0
                                       for at in ats] + [(0.0, 0.0)])
        self.log_floor = log_floor_table(
            cfg.clutter_floor, cfg.cut_sigma2 + cfg.lane_norm * math.log(cfg.max_lanes) + 1.0)

    def focused(self, arm: int, share: float) -> np.ndarray:
        """``P_polish`` with a share ``share`` of the arm moves on arm slot ``arm``."""
        P = self.P_polish.copy()
        P[P_FOCUS], P[P_FOCUS_P] = arm, share
        return P
