"""Where the real data are found: beside the checkout, also from an installed copy."""

from __future__ import annotations

import sys

from intersection_estimator.scenarios import sumo_net


def test_an_installed_copy_finds_shared_beside_the_checkout_of_its_venv(tmp_path, monkeypatch):
    checkout = tmp_path / 'work' / 'repo'
    venv = checkout / '.venv'
    site = venv / 'lib' / 'python3.11' / 'site-packages' / 'intersection_estimator' / 'scenarios'
    site.mkdir(parents=True)
    (tmp_path / 'work' / 'shared' / 'realdata').mkdir(parents=True)
    monkeypatch.delenv('IE_REALDATA', raising=False)
    monkeypatch.setattr(sumo_net, '__file__', str(site / 'sumo_net.py'))
    monkeypatch.setattr(sys, 'prefix', str(venv))
    monkeypatch.chdir(tmp_path)
    assert sumo_net.realdata_dir() == (tmp_path / 'work' / 'shared' / 'realdata').resolve()
    monkeypatch.setenv('IE_REALDATA', str(tmp_path / 'elsewhere'))
    assert sumo_net.realdata_dir() == tmp_path / 'elsewhere'
