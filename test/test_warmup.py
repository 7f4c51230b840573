"""pipeline.warmup: the one warm-up, without the simulator, reaching every compiled step."""

import os
from pathlib import Path
import subprocess
import sys
import textwrap

ROOT = Path(__file__).resolve().parents[1]

_PROBE = textwrap.dedent('''
    import sys
    from intersection_estimator.pipeline import warmup
    warmup()
    from intersection_estimator import observability
    from intersection_estimator.lanes import mcmc as lanes_mcmc
    from intersection_estimator.topology import descent, init, mcmc, preprocess, refit, voxels
    print('sim' if 'intersection_estimator.sim' in sys.modules else 'no-sim')
    print(hasattr(__import__('intersection_estimator.topology', fromlist=['x']), 'warmup'))
    for f in (refit.refit_arm, refit.refit_lane_steps, mcmc.run_chain, init.lane_guess, init.irls_center,
              preprocess.split_tracks, voxels.radar_voxels, voxels.grid_voxel_index,
              lanes_mcmc.run_chain, observability._occupied_squares, observability._bin_median_pass,
              observability._track_extents, observability._moving_mask):
        print(f.__name__, len(f.signatures))
''')


def test_warmup_compiles_every_step_without_the_simulator():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, '-c', _PROBE], env=env, cwd=ROOT, check=True,
                         capture_output=True, text=True, timeout=600).stdout.split('\n')
    assert out[0] == 'no-sim'
    assert out[1] == 'False'                 # one warmup: pipeline.warmup only
    counts = dict(line.split() for line in out[2:] if line)
    assert all(int(n) >= 1 for n in counts.values()), counts
    assert int(counts['refit_arm']) == 1     # the refits (the descent screens with refit_lane_steps)
