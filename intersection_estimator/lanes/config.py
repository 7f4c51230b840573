"""Configuration of the lane-course step (paper §III)."""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..ranges import check_labels, check_table

__all__ = ['LaneConfig']

# name -> (interval, what): see intersection_estimator/ranges.py
_RANGES = {
    'station_spacing': ('[0.5, 20.0]', 'distance between border support points [m]'),
    'connector_spacing': ('[0.2, 20.0]', 'distance between connector support points [m]'),
    'connector_min_stations': ('[3, 1000]', 'fewest support points of a connector'),
    'connector_arc': ('[0, 1]', '1: connectors start as arc-like cubic Bezier curves tangent to '
                          'their lanes, 0: straight (paper)'),
    'connector_traffic': ('[0, 1]', '1: connectors shaped by their traffic (lanes/spline.py, cubic '
                              'B-spline least squares), the arc/straight start only without it'),
    'traffic_presmooth': ('[1, 51]', 'moving-average length of the trajectory pieces [points]'),
    'traffic_ctrl_spacing': ('[0.5, 50.0]', 'chord per control point of a traffic connector [m]'),
    'traffic_smooth': ('[0.0, 1e6]', 'second-difference penalty on its control points (the largest '
                       'candidate when traffic_smooth_steps >= 2)'),
    'traffic_smooth_min': ('[0.0, 1e6]', 'smallest candidate penalty of a traffic connector'),
    'traffic_smooth_steps': ('[0, 50]', 'candidate penalties from traffic_smooth_min to traffic_smooth '
                             '(log spaced), the traffic picks one per connector (Mallows\' or '
                             'Akaike\'s criterion, traffic_noise; lanes/spline.py); < 2: '
                             'traffic_smooth alone'),
    'traffic_noise': ('[0, 1]', '1: the penalty is chosen against the positions\' noise read from '
                      'all trajectories (Mallows\' criterion, lanes/spline.py), 0: against each '
                      'connector\'s own residuals (Akaike\'s)'),
    'traffic_min_points': ('[3, 1e6]', 'fewest trajectory points to shape a connector'),
    'traffic_select': ('[0.0, 1000.0]', 'the fit replaces the start shape only when better by this '
                       'per parameter (2: Akaike; 0: always)'),
    'skip_labels': (None, 'classification labels (Autoware ids) of tracked road users left out of '
                    'the lane course (e.g. 6, 7: cyclists ride at the kerb, pedestrians cross); '
                    '(): every track; node parameter weak_labels'),
    'follow_lanes': ('[0, 1]', '1: entering/leaving lanelets shaped by their traffic (lanes/follow.py), '
                     '0: straight along the arm (paper)'),
    'follow_ctrl_spacing': ('[1.0, 100.0]', 'axis distance per control point of that shift [m]'),
    'follow_smooth': ('[0.0, 1e6]', 'second-difference penalty on its coefficients'),
    'follow_select': ('[0.0, 1000.0]', 'the shift is kept only when better by this per effective '
                      'degree of freedom (2: Akaike; 0: always)'),
    'follow_min_points': ('[4, 1e6]', 'fewest trajectory points to shape an arm direction / lane'),
    'follow_gate': ('[0.1, 20.0]', 'residuals beyond this after a first fit are dropped [m]'),
    'follow_iters': ('[0, 10]', 'corrections of that shift measured along the shifted axis\'s normal'),
    'follow_stop_margin': ('[0.0, 50.0]', 'points this close beyond the stop line do not shape the '
                           'lanes (turning traffic) [m]'),
    'follow_max_weight': ('[0.01, 100.0]', 'a point weighs the metres driven around it, at most this [m]'),
    'follow_corr_length': ('[0.01, 1000.0]', 'metres of one vehicle\'s path that count as one '
                           'observation in the selection [m]'),
    'follow_per_lane': ('[0, 3]', 'each lane with traffic also gets its own deviation: 1 entering '
                        'and leaving lanes, 2 entering lanes only, 3 entering lanes and a '
                        'constant offset per leaving lane, 0 none'),
    'follow_reassign': ('[0, 1]', '1: the parts of a bent direction are re-assigned to its lanes '
                        'by their offset from the shifted axis'),
    'halt_stops': ('[0, 1]', '1: stop lines moved in to where the vehicles halt (lanes/halts.py)'),
    'halt_follow': ('[0, 1]', '1: each halted vehicle is one point of its entering lane in the '
                    'follow fit (lanes/halts.py, lanes/follow.py)'),
    'halt_speed': ('(0.0, 5.0]', 'a vehicle slower than this halts [m/s]'),
    'halt_min_s': ('(0.0, 60.0]', 'a halt lasts at least this long [s]'),
    'halt_pair_m': ('[0.0, 20.0]', 'a halt is the stop line when another vehicle halted within '
                    'this along the arm [m]'),
    'halt_max_move': ('[0.0, 100.0]', 'halt_stops moves a stop line in by at most this [m]'),
    'stop_fit': ('[0, 1]', '1: fit the stop distances to the turning traffic (lanes/stops.py)'),
    'stop_search': ('[0.0, 20.0]', 'search range around the geometric stop distance [m]'),
    'stop_step': ('[0.01, 5.0]', 'grid step of the stop-distance search [m]'),
    'stop_clip': ('[0.1, 50.0]', 'distances are clipped here in the stop-distance fit [m]'),
    'stop_sweeps': ('[1, 20]', 'coordinate-descent sweeps over the arms in the stop fit'),
    'refit_lanes': ('[0, 10]', 'rounds of re-fitting arm directions and lane positions to the traffic '
                    'and re-assigning the trajectory parts'),
    'fit_margin': ('[0.0, 100.0]', 'lane re-fit uses part points this far beyond the stop line [m]'),
    'min_fit_points': ('[2, 1e6]', 'fewest points to re-fit an arm direction'),
    'max_refit_angle_deg': ('[0.0, 90.0]', 'largest accepted change of an arm direction [deg]'),
    'lane_prior_points': ('[0.0, 1e6]', 'pseudo points of the topology lane position in the re-fit'),
    'complete_partial': ('[0, 1]', '1: give one-sided trajectories their other lane by path fit'),
    'complete_min_points': ('[1, 1e6]', 'fewest points inside the stop line for that'),
    'complete_max_cost': ('[0.0, 100.0]', 'largest mean clipped squared distance to the path [m^2]'),
    'complete_min_ratio': ('[1.0, 100.0]', 'runner-up path must cost this many times more'),
    'arm_length_min': ('[5.0, 500.0]', 'shortest entering/leaving lanelet [m]'),
    'arm_length_max': ('[5.0, 500.0]', 'longest entering/leaving lanelet [m]'),
    'stop_margin': ('[0.0, 20.0]', 'extra distance of the stop line beyond the corner of two arms [m]'),
    'kerb_radius': ('[0.0, 50.0]', 'radius of the rounded kerb between two arms [m]'),
    'assign_inside': ('[0.0, 50.0]', 'part points this far inside the stop line still count for '
                      'the lane assignment (a track seen only a few metres beyond it) [m]'),
    'min_part_length': ('[0.0, 200.0]', 'shortest extent along its arm of a trajectory part [m]'),
    'stop_min': ('[0.0, 100.0]', 'smallest stop-line distance from the center [m]'),
    'stop_max': ('[0.0, 200.0]', 'largest stop-line distance from the center [m]'),
    'min_part_points': ('[1, 1000]', 'fewest points of a trajectory part that gets a lane'),
    'assign_reach': ('(0, inf]', 'an entering part is assigned, and places its lane, by its points this '
                     'far beyond the stop line [m] (inf: all, paper)'),
    'assign_gate': ('[0.1, 50.0]', 'largest distance of a part mean to its lane center line [m]'),
    'min_connector_evidence': ('[1, 1000]', 'trajectories needed to create a connector'),
    'point_gate': ('[0.1, 50.0]', 'trajectory points farther from their lane sequence are ignored [m]'),
    'window_segments': ('[1, 2]', 'center-line segments a point is scored against (nearest [+ next])'),
    'sigma_perp': ('[0.01, 10.0]', 'std of d_perp in the likelihood [m] (paper §III-C)'),
    'outlier_weight': ('[0.0, 1.0]', 'weight of a uniform outlier component per point'),
    'sigma_delta': ('[1e-3, 10.0]', 'std of the smoothness delta_l per lanelet [rad] (paper §III-C)'),
    'tau': ('[0.0, 1000.0]', 'exponent tau of the shared-border term s(I2)^tau'),
    'width_min': ('[0.5, 10.0]', 'narrowest lanelet [m]'),
    'width_max': ('[0.5, 20.0]', 'widest lanelet [m]'),
    'merge_radius': ('[0.0, 5.0]', 'border points closer than this are split/merge candidates [m]'),
    'step_center': ('[1e-3, 5.0]', 'std of a center-point move [m]'),
    'step_border': ('[1e-3, 5.0]', 'std of a border-point move [m]'),
    'split_max': ('[0.0, 5.0]', 'largest split distance Delta b [m] (paper: 0.6)'),
    'p_center': ('[0.0, 1.0]', 'probability of a center-point move'),
    'p_border': ('[0.0, 1.0]', 'probability of a border-point move'),
    'p_split': ('[0.0, 1.0]', 'probability of a split move'),
    'p_merge': ('[0.0, 1.0]', 'probability of a merge move'),
    'temp_start': ('[1e-4, 1e4]', 'annealing temperature at sample 0'),
    'temp_end': ('[1e-4, 1e4]', 'annealing temperature after anneal_samples'),
    'anneal_samples': ('[1, 1e9]', 'length of the geometric annealing schedule'),
    'warm_tolerance': ('[0.0, 100.0]', 'warm start only while the new initial course is this close [m]'),
    'warm_from_start': ('[0, 1]', "1: ... to the start the chain was built from; 0: to the chain's "
                        'current course'),
    'keep_best': ('[0, 1]', '1: end each run in the best state seen (MAP), 0: in the final state'),
    'refine': ('[0, 1]', 'penalised least-squares refinement (Meyer 2020 style) after the MCMC'),
    'refine_init': ('[0, 1]', 'penalised least-squares refinement of the initialisation'),
    'refine_select': ('[0.0, 1000.0]', 'refine_init: a connector keeps its refined shape only when '
                      'better by this per effective parameter (0: always)'),
    'refine_min_share': ('[0.0, 1.0]', 'refine_init: only where the start\'s residuals count at least '
                         'this share of their points as independent, (1 - rho) / (1 + rho) by their '
                         'lag-1 correlation rho (0: always)'),
    'refine_smooth': ('[0.0, 1e6]', 'weight of the second-difference penalty of the refinement'),
    'refine_smooth_connector': ('[0.0, 1e6]', 'second-difference weight inside connectors'),
    'refine_keep_shape': ('[0, 1]', '1: penalise second differences relative to the initial shape'),
    'refine_jerk': ('[0.0, 1e6]', 'weight of the third-difference penalty of the refinement'),
    'refine_width': ('[0.0, 1e6]', 'weight pulling lane widths to their topology width'),
    'refine_iters': ('[1, 50]', 'Gauss-Newton iterations of the refinement'),
    'refine_huber': ('[0.01, 100.0]', 'Huber threshold of the refinement residuals [m]'),
}


@dataclass(frozen=True)
class LaneConfig:
    """Parameters of :class:`LaneCourseEstimator`; ``validate()`` checks their ranges."""

    station_spacing: float = 2.5
    connector_spacing: float = 1.0
    connector_min_stations: int = 6
    connector_arc: int = 1
    connector_traffic: int = 1
    traffic_presmooth: int = 5
    traffic_ctrl_spacing: float = 4.0
    traffic_smooth: float = 10.0
    traffic_smooth_min: float = 0.01
    traffic_smooth_steps: int = 4
    traffic_noise: int = 1
    traffic_min_points: int = 10
    traffic_select: float = 1.0      # docs/real_junctions.md, "Connectors: half the penalty for the traffic's shape"
    follow_lanes: int = 1
    skip_labels: tuple = (6, 7)
    follow_ctrl_spacing: float = 10.0
    follow_smooth: float = 0.5
    follow_select: float = 2.0
    follow_min_points: int = 20
    follow_gate: float = 2.0
    follow_iters: int = 2
    follow_stop_margin: float = 0.0
    follow_max_weight: float = 3.0
    follow_corr_length: float = 4.0
    follow_per_lane: int = 3
    follow_reassign: int = 1
    halt_stops: int = 0              # docs/real_junctions.md, "Halted vehicles: stop lines and lanes"
    # (off: capped at 5 m it gains recall, but the never-tuned seeds' connectors lose 1.2 cm)
    halt_follow: int = 1
    halt_speed: float = 0.5
    halt_min_s: float = 2.0
    halt_pair_m: float = 2.0
    halt_max_move: float = 5.0
    stop_fit: int = 1
    stop_search: float = 2.0
    stop_step: float = 0.25
    stop_clip: float = 2.0
    stop_sweeps: int = 2
    refit_lanes: int = 1
    fit_margin: float = 0.0
    min_fit_points: int = 20
    max_refit_angle_deg: float = 10.0
    lane_prior_points: float = 30.0
    complete_partial: int = 1
    complete_min_points: int = 5
    complete_max_cost: float = 1.5
    complete_min_ratio: float = 1.5
    arm_length_min: float = 20.0
    arm_length_max: float = 120.0
    stop_margin: float = 2.5
    kerb_radius: float = 5.0
    assign_inside: float = 9.0
    min_part_length: float = 5.0
    stop_min: float = 3.0
    stop_max: float = 100.0
    min_part_points: int = 3
    assign_gate: float = 6.0
    assign_reach: float = 35.0       # docs/real_junctions.md, "Lanes placed next to the stop line"
    min_connector_evidence: int = 1
    point_gate: float = 6.0
    window_segments: int = 1
    sigma_perp: float = 1.0
    outlier_weight: float = 0.0
    sigma_delta: float = 0.15
    tau: float = 1.0
    width_min: float = 2.0
    width_max: float = 6.0
    merge_radius: float = 0.6
    step_center: float = 0.05
    step_border: float = 0.05
    split_max: float = 0.6
    p_center: float = 0.6
    p_border: float = 0.2
    p_split: float = 0.1
    p_merge: float = 0.1
    temp_start: float = 0.05
    temp_end: float = 0.02
    anneal_samples: int = 20000
    warm_tolerance: float = 0.3
    warm_from_start: int = 1         # docs/real_junctions.md, "Stop 55"
    keep_best: int = 1
    refine: int = 0
    refine_init: int = 1             # docs/real_junctions.md, "Stop 55"
    refine_select: float = 2.0       # docs/real_junctions.md, "Stop 54", "Stop 55"
    refine_min_share: float = 0.33   # docs/real_junctions.md, "Stop 55"
    refine_smooth: float = 1e4
    refine_smooth_connector: float = 300.0
    refine_keep_shape: int = 1
    refine_jerk: float = 0.0
    refine_width: float = 100.0
    refine_iters: int = 4
    refine_huber: float = 2.0

    def validate(self) -> 'LaneConfig':
        """Raise ``ValueError`` naming the first parameter outside its allowed range."""
        check_table(self, {f.name: _RANGES[f.name] for f in fields(self)})
        check_labels(self, 'skip_labels')
        if self.arm_length_min > self.arm_length_max:
            raise ValueError('LaneConfig.arm_length_min must be <= arm_length_max')
        if self.stop_min > self.stop_max:
            raise ValueError('LaneConfig.stop_min must be <= stop_max')
        if self.width_min >= self.width_max:
            raise ValueError('LaneConfig.width_min must be < width_max')
        if self.p_center + self.p_border + self.p_split + self.p_merge <= 0:
            raise ValueError('LaneConfig.p_center+p_border+p_split+p_merge must be > 0')
        return self
