"""``intersection-estimator demo``: the README's first command, end to end on the bundled bag."""

from __future__ import annotations

import json
import os
import subprocess

from conftest import script


def test_demo_replays_the_bundled_bag_and_scores_it_against_its_ground_truth(tmp_path):
    out = tmp_path / 'demo_out'
    p = subprocess.run([script('intersection-estimator'), 'demo', '--out', str(out)],
                       capture_output=True, text=True, timeout=300,
                       env=dict(os.environ, PYTHONWARNINGS='ignore'))
    assert p.returncode == 0, p.stderr[-2000:]
    assert 'Traceback' not in p.stderr, p.stderr[-2000:]
    for name in ('estimate.json', 'lanelets.osm', 'estimate.png', 'output.mcap'):
        assert (out / name).stat().st_size > 0, name
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith('against ground truth:'))
    assert 'arm_correct True' in line and 'topology_correct True' in line, line
    est = json.loads((out / 'estimate.json').read_text())
    assert len(est['arms']) == 4 and any(lane['kind'] == 'connector' for lane in est['lanes'])
