"""Issue 8: same bag + same seed -> byte-identical estimate.json, across processes.

Two ``replay`` processes run at once (each with its own hash seed, so nothing may depend on
set or dict order of strings) and their outputs are compared byte for byte.
"""

from __future__ import annotations

import json

from test_reliability_replay import bags, replay_all  # noqa: F401 - the module fixture


def test_replay_twice_gives_byte_identical_estimate(bags, tmp_path):  # noqa: F811
    results = replay_all({'a': (bags['good'], tmp_path / 'a', '--seed', '7'),
                          'b': (bags['good'], tmp_path / 'b', '--seed', '7'),
                          'c': (bags['good'], tmp_path / 'c', '--seed', '8')}, bags)
    for name, (code, stdout, stderr) in results.items():
        assert code == 0, (name, stdout, stderr)
    a, b, c = ((tmp_path / d / 'estimate.json').read_bytes() for d in ('a', 'b', 'c'))
    assert a == b
    assert json.loads(a)['arms'] and json.loads(a)['lanes']
    # the seed is what makes them equal: another seed samples other chains
    assert c != a
