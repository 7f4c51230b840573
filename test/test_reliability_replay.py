"""Issue 8: ``intersection-estimator replay`` over damaged input exits non-zero with one line on stderr.

Truncated and corrupt bags still give an estimate from what could be read (exit 2, said on
stderr); a missing path, an empty directory, a text file named .mcap, a bag without a usable
topic give exit 1 and nothing else. Runs the installed console script as the user would.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import shutil
import subprocess

import pytest

from conftest import script

SEED = 3                                       # a short scenario (21 s)
PARAMS = """intersection_estimator:
  ros__parameters:
    topology_samples: 300
    lane_samples: 300
    timer_period: 2.0
"""


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """A good scenario bag and its damaged copies, a bag with odometry only, and non-bags."""
    from intersection_estimator.bagio import write_scenario_bag
    from intersection_estimator.sim import simulate_scenario
    root = tmp_path_factory.mktemp('bags')
    sc = simulate_scenario(SEED)
    write_scenario_bag(sc, root / 'good', sensors=('tracked',), autoware=False)
    write_scenario_bag(sc, root / 'odometry_only', sensors=(), autoware=False)
    (mcap,) = (root / 'good').glob('*.mcap')
    data = mcap.read_bytes()
    out = {'good': root / 'good', 'odometry_only': root / 'odometry_only', 'root': root}
    for name, damaged in (('truncated', data[:len(data) * 6 // 10]),
                          ('corrupt', data[:len(data) // 2] + bytes(range(256)) * 16 + data[len(data) // 2 + 4096:]),
                          ('header_garbage', data[:8] + b'\x00\xff' * 2000 + data[4008:])):
        shutil.copytree(root / 'good', root / name)
        (root / name / mcap.name).write_bytes(damaged)
        out[name] = root / name
    (root / 'empty').mkdir()
    (root / 'x.mcap').write_text('this is not a bag\n')
    out.update(empty=root / 'empty', text=root / 'x.mcap', missing=root / 'no_such_bag')
    (root / 'params.yaml').write_text(PARAMS)
    out['params'] = root / 'params.yaml'
    return out


def replay_all(runs: dict, bags: dict) -> dict:
    """Run ``replay`` at once on ``{name: (bag, out_dir, *extra args)}``:
    name -> (returncode, stdout, non-empty stderr lines)."""
    procs = {}
    for name, (bag, out, *extra) in runs.items():
        args = [script('intersection-estimator'), 'replay', str(bag), '--out', str(out), '--quiet',
                '--params', str(bags['params']), *extra]
        procs[name] = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                       env=dict(os.environ, PYTHONWARNINGS='ignore'))
    results = {}
    for name, p in procs.items():
        stdout, stderr = p.communicate(timeout=240)
        results[name] = (p.returncode, stdout, [ln for ln in stderr.splitlines() if ln.strip()])
    return results


def test_unusable_input_exits_1_with_one_line(bags, tmp_path):
    cases = {'missing': 'missing', 'empty': 'not_a_bag', 'text': 'not_a_bag',
             'odometry_only': 'no_usable_topic', 'header_garbage': ''}
    results = replay_all({c: (bags[c], tmp_path / c) for c in cases}, bags)
    for case, reason in cases.items():
        code, stdout, stderr = results[case]
        assert code == 1, (case, code, stdout, stderr)
        assert len(stderr) == 1 and stderr[0].startswith('replay: ') and reason in stderr[0], (case, stderr)
        assert not (tmp_path / case / 'estimate.json').exists(), case


def test_damaged_bags_give_an_estimate_from_what_was_read_and_say_so(bags, tmp_path):
    results = replay_all({c: (bags[c], tmp_path / c) for c in ('truncated', 'corrupt')}, bags)
    for case, words in (('truncated', 'truncated'), ('corrupt', 'could not be read')):
        code, stdout, stderr = results[case]
        assert code == 2, (case, code, stdout, stderr)
        assert len(stderr) == 1 and 'bag damaged' in stderr[0] and words in stderr[0], (case, stderr)
        assert 'estimate from the' in stderr[0], stderr
        est = json.loads((tmp_path / case / 'estimate.json').read_text())
        assert est['arms'] and est['stats']['topology_samples'] > 0, (case, est['stats'])
