"""A robot that only localizes: vbn_common, landmark_db and landmark_localizer, nothing else.

The three runtime packages and the third-party modules their ``package.xml`` files name
(pinned by ``requirements.txt``) are installed into a fresh virtual environment, which is
then shown to hold neither the builder, the worlds and the benchmarks nor matplotlib,
pycolmap and evo. From that environment the localizer node runs on ``bags/room_run``
(played and recorded by that environment's ``vbn play`` and ``vbn record``) against a
database built beforehand, and poses the run.

Slow (a virtual environment of its own: about two minutes), so it is marked ``install``
and left out of the default run: ``make test-install`` runs it, and CI runs it after
``make test``.
"""
from __future__ import annotations

from pathlib import Path
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
from paths import REPO
import pytest
from ros_harness import NodeProcess

pytestmark = [pytest.mark.integration, pytest.mark.install]

ROOT = REPO
SRC = ROOT / 'ros2_ws' / 'src'
RUNTIME = ('vbn_common', 'landmark_db', 'landmark_localizer')
#: The pip requirement of each rosdep key the runtime packages declare (None: it comes
#: with another requirement, or is built in the workspace, as tf2_msgs is).
PIP = {
    'python3-numpy': 'numpy', 'python3-scipy': 'scipy', 'python3-numba': 'numba',
    'python3-opencv': 'opencv-python-headless', 'python3-yaml': 'pyyaml',
    'python3-ruamel.yaml': 'ruamel.yaml', 'python3-rosbags-pip': 'rosbags',
    'mcap-ros2-support': 'mcap-ros2-support', 'rclpy': 'ros-jazzy-rclpy[fastrtps]',
    'ament_index_python': None, 'tf2_msgs': None,
}
#: Message and service packages: all in the wheels' common interfaces.
INTERFACES = 'ros-jazzy-common-interfaces'


def _declared(package: str) -> list[str]:
    root = ET.parse(SRC / package / 'package.xml').getroot()
    return [e.text for tag in ('depend', 'exec_depend') for e in root.findall(tag)]


def runtime_requirements() -> list[str]:
    """The pip requirements of the runtime packages, from their ``package.xml`` files."""
    wanted = {INTERFACES, 'setuptools', 'wheel'}  # setuptools and wheel install ours
    for package in RUNTIME:
        for key in _declared(package):
            if key in RUNTIME:
                continue
            if key.endswith(('_msgs', '_srvs', '_interfaces')) and key not in PIP:
                continue
            assert key in PIP, f'{package} declares {key}: give it a pip requirement here'
            if PIP[key]:
                wanted.add(PIP[key])
    return sorted(wanted)


def test_the_runtime_requirements_leave_out_the_lab() -> None:
    wanted = runtime_requirements()
    assert 'numpy' in wanted and 'ros-jazzy-rclpy[fastrtps]' in wanted
    assert not {'matplotlib', 'pycolmap', 'evo', 'scikit-image', 'gtsam', 'tqdm'} & set(wanted)


@pytest.fixture(scope='module')
def runtime_venv(tmp_path_factory) -> Path:
    """A fresh virtual environment with only the three runtime packages installed."""
    venv = tmp_path_factory.mktemp('runtime') / 'venv'
    subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True)
    python = venv / 'bin' / 'python'
    pip = [str(python), '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check']
    # The lock's versions as constraints (pip takes no extras there).
    constraints = venv.parent / 'constraints.txt'
    constraints.write_text(re.sub(r'\[[^\]]*\]', '', (ROOT / 'requirements.txt').read_text()))
    subprocess.run([*pip, '-c', str(constraints), *runtime_requirements()], check=True,
                   timeout=1200)
    # From copies: setuptools builds in the package's folder.
    copies = [shutil.copytree(SRC / p, venv.parent / 'src' / p) for p in RUNTIME]
    subprocess.run([*pip, '--no-deps', '--no-build-isolation', *map(str, copies)],
                   check=True, timeout=600)
    return venv


def _env(venv: Path, ros_env: dict[str, str]) -> dict[str, str]:
    """The robot's environment: the venv, the workspace's tf2_msgs, this run's DDS domain.

    Built from nothing rather than from this process's environment, which holds the full
    workspace (and the wheels' library path, which the venv's own bootstrap must set).
    """
    tf2 = ROOT / 'ros2_ws' / 'install' / 'tf2_msgs'
    site = next((tf2 / 'lib').glob('python3*/site-packages'))
    kept = ('HOME', 'LANG', 'LC_ALL', 'TMPDIR', 'OPENBLAS_CORETYPE', 'OPENBLAS_L2_SIZE',
            'ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'PYTHONUNBUFFERED')
    env = {k: ros_env[k] for k in kept if k in ros_env}
    env.update(VIRTUAL_ENV=str(venv), PATH=f'{venv / "bin"}:/usr/bin:/bin',
               PYTHONPATH=str(site), AMENT_PREFIX_PATH=f'{venv}:{tf2}',
               LD_LIBRARY_PATH=str(tf2 / 'lib'), PYTHONNOUSERSITE='1')
    return env


def test_the_runtime_venv_holds_the_localizer_and_nothing_of_the_lab(runtime_venv: Path,
                                                                     ros_env) -> None:
    env = _env(runtime_venv, ros_env)
    script = (
        'import importlib.util as u\n'
        'mods = ["vbn_common", "landmark_db", "landmark_localizer", "rclpy", "tf2_msgs",\n'
        '        "visibility_builder", "vbn_worlds", "vbn_bench", "matplotlib", "pycolmap",\n'
        '        "evo", "skimage", "gtsam"]\n'
        'print(" ".join(m for m in mods if u.find_spec(m) is not None))\n')
    found = subprocess.run([str(runtime_venv / 'bin' / 'python'), '-c', script], env=env,
                           capture_output=True, text=True, check=True).stdout.split()
    assert found == ['vbn_common', 'landmark_db', 'landmark_localizer', 'rclpy', 'tf2_msgs']
    commands = subprocess.run(['vbn', '--help'], env=env, capture_output=True, text=True,
                              check=True).stdout
    for name in ('play', 'record', 'echo', 'db-info', 'decompose'):
        assert f'    {name} ' in commands
    for name in ('build', 'render', 'localize', 'demo', 'bench-localize'):
        assert f'    {name} ' not in commands


def test_the_runtime_venv_localizes_the_room_run(runtime_venv: Path, room_db: Path,
                                                 ros_env, tmp_path: Path) -> None:
    env = _env(runtime_venv, ros_env)
    started: list[NodeProcess] = []

    def start(args: list[str], name: str) -> NodeProcess:
        started.append(NodeProcess(args, env, tmp_path / f'{name}.log'))
        return started[-1]

    recorded = tmp_path / 'recorded'
    try:
        node = start(['localizer', '--ros-args', '-p', f'db:={room_db}'], 'localizer')
        node.wait_for_output('localizer ready', timeout=180)
        recorder = start(['vbn', 'record', '--topics', '/localizer/pose', '--out',
                          str(recorded)], 'record')
        recorder.wait_for_output('recording into', timeout=60)
        player = start(['vbn', 'play', str(ROOT / 'bags' / 'room_run'),
                        '--wait-for-subscribers', '--wait-timeout', '120', '--rate', '0.5',
                        '--topics', '/camera/image_raw/compressed', '/camera/camera_info',
                        '/odom'], 'play')
        assert player.wait(timeout=600) == 0, player.output
        recorder.wait_for_output(r'recording /localizer/pose', timeout=60)
    finally:
        for process in reversed(started):
            process.stop()
    assert node.popen.returncode in (0, -2, 130), node.output
    from rosbags.highlevel import AnyReader

    with AnyReader([recorded]) as reader:
        stamps = np.array([t for _c, t, _r in reader.messages()])
    # 439 frames at half speed: the node poses nearly all of them (the DDS tests' bar).
    assert len(stamps) >= 0.9 * 439, f'{len(stamps)} poses; {node.output[-2000:]}'


if __name__ == '__main__':
    sys.exit(pytest.main([__file__, '-q', '-m', 'install', *sys.argv[1:]]))
