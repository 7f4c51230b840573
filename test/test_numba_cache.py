"""numba cache safety: an edit of one kernel file recompiles its callers in other files."""

from __future__ import annotations

import math
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import textwrap

import pytest

import intersection_estimator
from intersection_estimator import _numba_cache

PKG = Path(intersection_estimator.__file__).resolve().parent

# moves.add_arm_angle_logdensity (moves.py) calls state.largest_gap (state.py): a compiled
# caller in one file, its callee in another.
_PROBE = textwrap.dedent('''
    import numpy as np
    import numba
    from intersection_estimator.model import Arm, Intersection
    from intersection_estimator.topology import TopologyConfig
    from intersection_estimator.topology.moves import add_arm_angle_logdensity
    from intersection_estimator.topology.state import pack_state
    S = pack_state(Intersection(center=np.zeros(2), arms=[Arm(angle=0.0), Arm(angle=1.0)]))
    P = TopologyConfig(split_span_deg=0.0).kernel_params()
    print(repr(float(add_arm_angle_logdensity(S, 2.0, P))), numba.config.CACHE_DIR)
''')


def _probe(root: Path, cache: Path) -> tuple[float, str]:
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, '-c', _PROBE], env=env, cwd=root, check=True,
                         capture_output=True, text=True, timeout=240).stdout.split()
    return float(out[0]), out[1]


def test_every_module_that_imports_numba_keys_the_cache():
    keyed = set(_numba_cache.kernel_sources())
    for p in PKG.rglob('*.py'):
        if re.search(r'^\s*(import numba|from numba)', p.read_text(), re.M) and p.name != '_numba_cache.py':
            assert p in keyed, p
    assert PKG / 'topology' / 'state.py' in keyed and PKG / 'lanes' / 'mcmc.py' in keyed


def test_the_package_import_points_numba_at_the_keyed_directory():
    import numba
    assert numba.config.CACHE_DIR == str(_numba_cache.cache_dir())
    assert _numba_cache.cache_dir().name == _numba_cache.source_key()


def test_editing_a_callee_in_another_file_recompiles_the_caller(tmp_path):
    """Run 1 compiles and caches the caller; the callee's file is edited (largest_gap now
    reports half the gap); run 2 must see the edit although the caller's file is
    unchanged -- with numba's per-file keys it would load the stale caller."""
    root = tmp_path / 'src'
    shutil.copytree(PKG, root / 'intersection_estimator',
                    ignore=shutil.ignore_patterns('__pycache__'))
    cache = tmp_path / 'cache'
    v1, dir1 = _probe(root, cache)
    assert any(Path(dir1).rglob('moves.add_arm_angle_logdensity-*.nbi'))   # it was cached
    state = root / 'intersection_estimator' / 'topology' / 'state.py'
    src = state.read_text()
    assert src.count('    return start, best\n') == 1
    state.write_text(src.replace('    return start, best\n', '    return start, 0.5 * best\n'))
    v2, dir2 = _probe(root, cache)
    assert dir2 != dir1
    # gap from 1 rad to 2 pi: feasible width L = g - 2 min_sep; density 0.5 / L
    ms, g = math.radians(30.0), 2 * math.pi - 1.0
    assert v1 == pytest.approx(-math.log(2 * (g - 2 * ms)))
    assert v2 == pytest.approx(-math.log(2 * (0.5 * g - 2 * ms)))
    v3, dir3 = _probe(root, cache)                 # unchanged again: same key, same value
    assert (v3, dir3) == (v2, dir2)
