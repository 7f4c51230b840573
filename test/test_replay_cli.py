"""Issue 16, the command line as a user meets it: one-line errors with non-zero exits, help
without Sphinx markup, ``--out`` over old results, exit code 3 and the reason printed.
Runs the installed console script (``make setup``)."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from conftest import script

from test_replay_routes import params, synthetic_bag


def run(*args, timeout=240, cwd=None):
    p = subprocess.run([script('intersection-estimator'), *map(str, args)], capture_output=True, text=True,
                       timeout=timeout, env=dict(os.environ, PYTHONWARNINGS='ignore'), cwd=cwd)
    return p.returncode, p.stdout, [ln for ln in p.stderr.splitlines() if ln.strip()]


@pytest.mark.parametrize('args, words', [
    (('evaluate', 'no_such_estimate.json', 'no_such_gt.json'), 'no such file'),
    (('bench', '--n', '0'), '--n'),
    (('bench', '--seed', '-1'), '--seed'),
    (('simulate', '--seed', '-1', '--out', 'x'), '--seed'),
])
def test_bad_arguments_give_one_line_and_a_nonzero_exit(args, words, tmp_path):
    code, stdout, stderr = run(*args, cwd=tmp_path)
    assert code != 0, (args, stdout, stderr)
    assert len(stderr) == 1 and words in stderr[0] and 'Traceback' not in stderr[0], (args, stderr)
    assert not (tmp_path / 'x').exists()


def test_help_has_no_sphinx_markup_and_demo_out_is_explained():
    for cmd in ('replay', 'demo', 'simulate', 'evaluate', 'bench', 'soak'):
        code, stdout, _ = run(cmd, '--help')
        assert code == 0 and stdout, cmd
        for markup in ('``', ':class:', ':func:', ':mod:', ':data:', ':meth:', ':attr:'):
            assert markup not in stdout, (cmd, markup, stdout)
    _, demo, _ = run('demo', '--help')
    assert any(ln.split()[:2] == ['--out', 'OUT'] and 'output directory' in ln for ln in demo.splitlines()), demo
    _, rep, _ = run('replay', '--help')
    assert 'exit codes' in rep and '3 no intersection' in ' '.join(rep.split())


def test_no_intersection_exits_3_and_old_results_do_not_survive(tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    for name in ('estimate.png', 'lanelets.osm', 'estimate.json'):
        (out / name).write_text('old')
    (out / 'mine.txt').write_text('not the replay\'s')
    bag = synthetic_bag(tmp_path / 'bag', odometry=False)
    code, stdout, stderr = run('replay', bag, '--out', out, '--quiet', '--params', params(tmp_path))
    assert code == 3, (stdout, stderr)
    assert any('no intersection estimated' in ln and 'no_ego_pose' in ln for ln in stderr), stderr
    assert all(ln.startswith('replay: ') for ln in stderr), stderr
    assert json.loads((out / 'estimate.json').read_text())['stats']['state'] == 'NO_DATA'
    assert not (out / 'estimate.png').exists() and not (out / 'lanelets.osm').exists()
    assert (out / 'mine.txt').exists() and (out / 'output.mcap').exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.out.')] == []   # no temp folder left


def test_a_failed_run_leaves_the_old_results_as_they_were(tmp_path, monkeypatch):
    from intersection_estimator import replay as R
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'estimate.json').write_text('old')
    bag = synthetic_bag(tmp_path / 'bag')

    def boom(*a, **k):
        raise RuntimeError('disk full')
    monkeypatch.setattr(R, '_write_files', boom)
    with pytest.raises(RuntimeError):
        R.replay([str(bag)], out, params_file=params(tmp_path), progress=False)
    assert sorted(p.name for p in out.iterdir()) == ['estimate.json']
    assert (out / 'estimate.json').read_text() == 'old'
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.out.')] == []
