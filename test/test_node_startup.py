"""Issue 16, start-up of the node process: a bad parameter is one line naming it (no
traceback, exit code 2); ``radar_topics: []`` runs; topics whose message package is not
installed are one error line each, naming the topic and the package; the launch file."""

from __future__ import annotations

import ast
import re

import pytest

from conftest import ROOT, script, wait_for


@pytest.mark.parametrize('arg, name', [('budget_ms:=-5.0', 'budget_ms'), ('budget_ms:=abc', 'budget_ms'),
                                       ('seed:=1.5', 'seed'), ('mount_x:=[1.0, 2.0]', 'mount_x')])
def test_bad_parameter_is_one_line_naming_it(node_process, arg, name):
    proc = node_process([script('intersection_estimator_node'), '--ros-args', '-p', arg])
    proc.proc.wait(60)
    out = proc.output()
    assert proc.proc.returncode == 2, out
    assert 'Traceback' not in out, out
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1 and name in lines[0], out


def test_empty_topic_list_and_missing_packages_at_startup(node_process, tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('intersection_estimator:\n  ros__parameters:\n    radar_topics: []\n'
                      '    radar_scan_topics: ["/radar/scan"]\n    autoware_object_topics: ["/aw/objects"]\n')
    proc = node_process([script('intersection_estimator_node'), '--ros-args', '--params-file', str(params)])
    assert wait_for(lambda: 'kernels ready' in proc.output() or not proc.alive(), 120), proc.output()
    assert proc.alive(), proc.output()
    out = proc.output()
    errors = [ln for ln in out.splitlines() if ln.startswith('[ERROR]')]
    assert len(errors) == 2, out
    assert '/radar/scan' in errors[0] and 'radar_msgs' in errors[0]
    assert '/aw/objects' in errors[1] and 'autoware_perception_msgs' in errors[1]
    assert 'radar_topics' not in ' '.join(re.findall(r'listening to .*', out))
    assert proc.stop() == 0 and 'Traceback' not in proc.output(), proc.output()


def test_launch_file_names_what_the_package_installs():
    """No ROS 2 `launch` here (not on PyPI): the file must parse, and name an installed
    executable, the shipped parameter file and the default topics it remaps."""
    path = ROOT / 'launch' / 'intersection_estimator.launch.py'
    tree = ast.parse(path.read_text())
    consts = {n.targets[0].id: ast.literal_eval(n.value) for n in tree.body
              if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Name)
              and isinstance(n.value, (ast.Constant, ast.Dict))}
    setup = (ROOT / 'setup.py').read_text()
    for exe in (consts['PLAIN'], consts['MANAGED']):
        assert f"'{exe} = " in setup
        script(exe)                                    # installed by `make setup`
    assert "'launch/*.launch.py'" in setup
    assert consts['PACKAGE'] == 'intersection_estimator'
    assert 'intersection_estimator.yaml' in path.read_text()
    yaml_text = (ROOT / 'config' / 'intersection_estimator.yaml').read_text()
    for topic in consts['REMAPS'].values():
        assert f'"{topic}"' in yaml_text, topic
    assert any(isinstance(n, ast.FunctionDef) and n.name == 'generate_launch_description' for n in tree.body)
