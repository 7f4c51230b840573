"""``intersection-estimator fleet`` with the local engine: changes.json, PNG, summary table,
a corrupt bag reported while the others go on (issue 17, slice 3)."""

from __future__ import annotations

import json
from pathlib import Path

from intersection_estimator.cli import main
from intersection_estimator.fleet.engine import bag_identity, expand_bags, seed_of

PARAMS = str(Path(__file__).with_name('fast_params.yaml'))


def test_fleet_local_reports_change_and_corrupt_bag(fleet_data, tmp_path, capsys):
    out = tmp_path / 'out'
    rc = main(['fleet', str(fleet_data['bags']), '--map', str(fleet_data['map']), '--out', str(out),
               '--params', PARAMS, '--quiet'])
    printed = capsys.readouterr().out
    assert rc == 2                                   # a bag failed, the rest went on
    doc = json.loads((out / 'changes.json').read_text())
    status = {b['bag']: b['status'] for b in doc['bags']}
    assert status == {'broken.mcap': 'failed', 'drive1': 'ok', 'drive2': 'ok'}
    assert 'failed: broken.mcap' in printed and 'X' in printed
    (inter,) = doc['intersections']
    moved = [c for c in inter['changes'] if c['kind'] == 'lane_moved']
    assert len(moved) == 1 and moved[0]['evidence']['drives_showing'] == 2
    assert 0.75 < moved[0]['evidence']['mean_offset_m'] < 1.3
    assert (out / f"changes_{inter['id']}.png").stat().st_size > 10_000
    assert str(tmp_path) not in (out / 'changes.json').read_text()     # no machine paths
    (fleet_data['root'] / 'local_changes.json').write_bytes((out / 'changes.json').read_bytes())


def test_bad_map_and_engine_refused(fleet_data, tmp_path, capsys):
    assert main(['fleet', str(fleet_data['bags']), '--map', str(tmp_path / 'none.osm'),
                 '--out', str(tmp_path)]) == 1
    assert 'prior map' in capsys.readouterr().err
    assert main(['fleet', str(fleet_data['bags']), '--map', str(fleet_data['map']), '--out', str(tmp_path),
                 '--workers', '0']) == 1
    assert 'workers' in capsys.readouterr().err


def test_bag_identity_is_content(fleet_data, tmp_path):
    bags = expand_bags([str(fleet_data['bags'])])
    assert [Path(b).name for b in bags] == ['broken.mcap', 'drive1', 'drive2']
    import shutil
    copy = shutil.copytree(bags[1], tmp_path / 'elsewhere')
    assert bag_identity(copy) == bag_identity(bags[1]) != bag_identity(bags[2])
    assert 0 <= seed_of(bag_identity(copy)) < 2 ** 31 - 1


def test_replay_node_and_cli_never_import_ray():
    import subprocess
    import sys
    code = ('import sys, intersection_estimator.replay, intersection_estimator.cli as c, '
            'intersection_estimator.fleet.cli, intersection_estimator.fleet.engine; c.build_parser(); '
            'import intersection_estimator.node; print("ray" in sys.modules, "rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.split() == ['False', 'True'], out.stderr
    core = ('import sys, intersection_estimator.fleet.changes, intersection_estimator.fleet.fuse, '
            'intersection_estimator.fleet.report, intersection_estimator.fleet.prior_map; '
            'print("rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', core], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.split() == ['False'], out.stderr


def test_a_drive_through_two_intersections_gives_two_estimates(tmp_path):
    """The adapter hands on every intersection replay kept, in drive order."""
    from intersection_estimator.bagio import write_drive_bag
    from intersection_estimator.fleet.engine import drive_estimates
    bag = write_drive_bag(tmp_path / 'drive', (3, 5))
    ests, damage = drive_estimates(str(bag), 0, str(Path(__file__).with_name('fast_params.yaml')))
    assert not damage and len(ests) == 2
    (i0, _, w0), (i1, _, w1) = ests
    assert list(i0.center) != list(i1.center)
    # each with the observations it rests on (the fleet map-matches their vehicles)
    assert len(w0) > 0 and len(w1) > 0 and (w0.track_id >= 0).any()


def test_corroboration_switches_are_recorded(fleet_data, tmp_path, capsys):
    """--no-corroborate / --any-lane-absence / --even-lane-choice / --no-empty-calibration reach
    the change rules
    (changes.json's config);
    the moved lane is found either way (its vehicles drive 1 m beside the mapped line).
    Without corroboration one drive's estimate alone claims: this drive's (its seed from the
    bag) leaving lanes of arm 1 sit a lane's share off the truth (0.74 m with the start's
    refinement off, 1.15 m with it on, docs/real_junctions.md "Stop 55"), which the drives
    of test_fleet_local_reports_change_and_corrupt_bag, with corroboration, do not confirm."""
    out = tmp_path / 'off'
    main(['fleet', str(fleet_data['bags'] / 'drive1'), '--map', str(fleet_data['map']), '--out', str(out),
          '--params', PARAMS, '--quiet', '--no-corroborate', '--any-lane-absence', '--even-lane-choice',
          '--no-empty-calibration'])
    doc = json.loads((out / 'changes.json').read_text())
    assert doc['config']['corroborate'] == 0 and doc['config']['turn_absence'] == 0
    assert doc['config']['share_from_traffic'] == 0 and doc['config']['empty_calibration'] == 0
    changes = doc['intersections'][0]['changes']
    assert {c['kind'] for c in changes} == {'lane_moved'}
    assert any(c['direction'] == 'in' and 0.75 < c['evidence']['mean_offset_m'] < 1.3 for c in changes)
    from intersection_estimator.fleet.changes import ChangeConfig
    assert ChangeConfig().corroborate == 1 and ChangeConfig().turn_absence == 1      # the defaults
    assert ChangeConfig().share_from_traffic == 1 and ChangeConfig().empty_calibration == 1
