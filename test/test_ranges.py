"""The one range-check style (``ranges.py``): intervals as written, bounds naming fields."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from intersection_estimator.ranges import check_range, check_table


@dataclass
class Cfg:
    a: float = 0.5
    b: float = 2.0
    c: int = 3


TABLE = {'a': ('(0, 1)', 'a share'), 'b': ('[a, inf)', 'at least a [m]'), 'c': (None, 'anything')}


def test_inside_passes_and_none_is_unchecked():
    check_table(Cfg(), TABLE)
    check_table(Cfg(c=-10**9), TABLE)


@pytest.mark.parametrize('kw, words', [
    (dict(a=0.0), 'Cfg.a=0.0 outside (0, 1) (a share)'),
    (dict(a=1.0), 'outside (0, 1)'),
    (dict(a=float('nan')), 'Cfg.a=nan'),
    (dict(b=0.25), 'Cfg.b=0.25 outside [a, inf) (at least a [m])'),
    (dict(a='x'), "Cfg.a='x'"),
])
def test_outside_names_field_value_interval_and_meaning(kw, words):
    with pytest.raises(ValueError, match=words.replace('(', r'\(').replace(')', r'\)').replace('[', r'\[')):
        check_table(Cfg(**kw), TABLE)


def test_label_and_closed_bounds():
    check_range(Cfg(a=1.0), 'a', '[0, 1]', 'closed')
    with pytest.raises(ValueError, match=r'^convergence\.a='):
        check_range(Cfg(a=2.0), 'a', '[0, 1]', 'closed', label='convergence')


def test_every_config_of_the_package_uses_it():
    """Each configuration refuses a bad value through the same message shape."""
    from dataclasses import replace
    from intersection_estimator.convergence import ConvergenceConfig
    from intersection_estimator.fleet.changes import ChangeConfig
    from intersection_estimator.lanes import LaneConfig
    from intersection_estimator.observability import ObservabilityConfig
    from intersection_estimator.pipeline import PipelineConfig
    from intersection_estimator.topology import TopologyConfig
    for cfg, name in ((ConvergenceConfig(), 'enter_s'), (ChangeConfig(), 'moved_m'), (LaneConfig(), 'sigma_perp'),
                      (ObservabilityConfig(), 'corridor_m'), (PipelineConfig(), 'window_s'),
                      (TopologyConfig(), 'chains')):
        cfg.validate()
        with pytest.raises(ValueError, match=rf'\.{name}=-1 outside '):
            replace(cfg, **{name: -1}).validate()
