"""Shared fixtures: an isolated ROS 2 environment per test run and node processes.

Every run gets its own ROS_DOMAIN_ID and a temporary ROS_HOME; DDS stays on localhost
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) with the fast-discovery Fast DDS profile.
Waits for discovery are bounded loops on matched counts, never bare sleeps.
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import pytest

ROOT = Path(__file__).resolve().parents[1]


_DOMAIN_LOCK = None   # held open for the life of this process


def _free_domain() -> int:
    """A ROS_DOMAIN_ID no other test run on this machine holds: an exclusive lock on a file
    per id (released by the OS when the process ends, even on a crash), searched from a
    pid-based start. Two runs in one domain would see each other's nodes and topics."""
    global _DOMAIN_LOCK
    import fcntl
    start = os.getpid() % 100
    for k in range(100):
        domain = 1 + (start + k) % 100
        f = open(os.path.join(tempfile.gettempdir(), f'ie_ros_domain_{domain}.lock'), 'w')
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        _DOMAIN_LOCK = f
        return domain
    return 1 + start


def _ros_env() -> dict:
    home = tempfile.mkdtemp(prefix='ie_ros_home_')
    return {
        'ROS_DOMAIN_ID': str(_free_domain()),
        'ROS_HOME': home,
        'ROS_LOG_DIR': os.path.join(home, 'log'),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'FASTRTPS_DEFAULT_PROFILES_FILE': str(ROOT / 'config' / 'fastdds_localhost.xml'),
        'AMENT_PREFIX_PATH': os.environ.get('AMENT_PREFIX_PATH') or sys.prefix,
        'PYTHONUNBUFFERED': '1',
    }


# Set before any test imports rclpy, so in-process participants use the same settings.
ROS_ENV = _ros_env()
os.environ.update(ROS_ENV)


def script(name: str) -> str:
    """Path of an installed console script, found where ``ros2 run`` looks first
    (``<prefix>/lib/intersection_estimator/`` of the ament index: colcon, ROS installs),
    then in this venv's ``bin/`` (``make setup``)."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    try:
        path = Path(get_package_prefix('intersection_estimator')) / 'lib' / 'intersection_estimator' / name
        if path.exists():
            return str(path)
    except (PackageNotFoundError, ValueError):
        pass
    path = Path(sys.prefix) / 'bin' / name
    found = str(path) if path.exists() else shutil.which(name)
    if not found:
        pytest.fail(f'console script {name!r} not installed: run `make setup`')
    return found


class NodeProcess:
    """A node started through its console script, always cleaned up."""

    def __init__(self, args: list[str], env: dict | None = None):
        self.log = tempfile.NamedTemporaryFile(prefix='ie_node_', suffix='.log', delete=False)
        full_env = dict(os.environ, **ROS_ENV, **(env or {}))
        full_env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
        self.proc = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT, env=full_env,
                                     start_new_session=True)

    def output(self) -> str:
        self.log.flush()
        return Path(self.log.name).read_text(errors='replace')

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        return self.proc.returncode


@pytest.fixture
def node_process():
    """Factory: ``node_process([args])`` starts a process; all are stopped at teardown."""
    started: list[NodeProcess] = []

    def start(args: list[str], env: dict | None = None) -> NodeProcess:
        p = NodeProcess(args, env)
        started.append(p)
        return p

    yield start
    for p in started:
        p.stop()


@pytest.fixture
def ros_context():
    """An rclpy context of its own for the test, shut down at teardown."""
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    ctx.try_shutdown()


def wait_for(predicate, timeout: float, spin=None, step: float = 0.05) -> bool:
    """Poll ``predicate`` (spinning ``spin(step)`` in between) until true or timeout."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        if spin is not None:
            spin(step)
        else:
            time.sleep(step)
    return bool(predicate())
