"""Parameters of the SUMO scenario family (issue 15.1), one frozen dataclass.

Ranges are closed ``(low, high)`` tuples; every draw goes through the case's seeded
``numpy.random.Generator`` (SUMO itself gets a seed drawn from it), so ``(seed,
SumoConfig)`` fixes the case.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ['SumoConfig', 'NETWORKS']

#: network sources of the family: generated junctions, the four real inD networks
NETWORKS = ('generated', 'ind')


@dataclass(frozen=True)
class SumoConfig:
    # --- which network ---------------------------------------------------------------
    ind_share: float = 0.2                          # share of cases on the inD networks
    # --- generated junctions -----------------------------------------------------------
    arms: tuple[int, int] = (3, 6)
    min_arm_angle_deg: float = 40.0                 # skewed angles, at least this apart
    lanes: tuple[int, int] = (1, 3)                 # per direction
    lane_width: tuple[float, float] = (3.0, 3.6)
    median_gap: tuple[float, float] = (0.0, 2.0)
    box_m: tuple[float, float] = (12.0, 20.0)       # where the approach line starts [m]
    offset_m: float = 5.0                           # arm axis misses the center by <= this
    curve_deg: float = 35.0                         # approach bends by up to this ...
    curve_start_m: tuple[float, float] = (10.0, 40.0)   # ... starting this far out
    arm_length_m: float = 160.0                     # node distance of the outer ends
    pocket_prob: float = 0.4                        # turn pocket (lane added) per arm
    pocket_m: tuple[float, float] = (30.0, 80.0)    # its length before the stop line
    neighbour_prob: float = 0.3                     # a neighbouring junction on one arm
    neighbour_m: tuple[float, float] = (25.0, 60.0)
    tls_prob: float = 0.6                           # traffic light (else priority)
    # --- demand ----------------------------------------------------------------------------
    zero_route_prob: float = 0.25                   # a from -> to relation without demand
    route_vph: tuple[float, float] = (100.0, 500.0)  # vehicles per hour of the others
    bicycle_share: float = 0.08
    truck_share: float = 0.05
    pedestrians_per_h: tuple[float, float] = (0.0, 600.0)
    parked: tuple[int, int] = (0, 6)                # parked cars at the kerb
    # --- time ------------------------------------------------------------------------------
    warmup_s: float = 30.0                          # traffic builds up (queues) first
    duration: tuple[float, float] = (30.0, 45.0)    # recorded window [s]
    step_s: float = 0.1
    gt_arm_length_m: float = 60.0                   # GT lanes this far out from the box

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}
