"""The package rules, read from the imports (AST): who may import whom, where rclpy may be.

``vbn_common`` imports no project package; ``landmark_db`` only ``vbn_common``; the
builder, the localizer and the worlds stand on both and never import each other; the
benchmarks stand on all of them and nothing stands on them. rclpy and message packages
appear only in the ROS glue modules listed here; no source file is over 600 lines; every
``package.xml`` declares exactly what its package imports; the packages a robot installs
to localize import no benchmark-only library; and no code of ours runs our own commands
as subprocesses.
"""
from __future__ import annotations

import ast
from pathlib import Path
import sys
import xml.etree.ElementTree as ET

from paths import REPO
import pytest

ROOT = REPO
SRC = ROOT / 'ros2_ws' / 'src'
PROJECT = ('vbn_common', 'landmark_db', 'visibility_builder', 'landmark_localizer',
           'vbn_worlds', 'vbn_bench')
#: What each package may import of the project (besides itself).
ALLOWED = {
    'vbn_common': set(),
    'landmark_db': {'vbn_common'},
    'visibility_builder': {'vbn_common', 'landmark_db'},
    'landmark_localizer': {'vbn_common', 'landmark_db'},
    'vbn_worlds': {'vbn_common', 'landmark_db'},
    'vbn_bench': {'vbn_common', 'landmark_db', 'visibility_builder', 'landmark_localizer',
                  'vbn_worlds'},
}
#: What a robot that only localizes installs.
RUNTIME = ('vbn_common', 'landmark_db', 'landmark_localizer')
#: Libraries only the benchmarks and reports use: no runtime package imports them.
BENCH_ONLY = {'matplotlib', 'evo', 'pycolmap'}
#: The ROS glue: the only modules that may import rclpy or message packages.
GLUE = {
    'vbn_common': {'dds_probe.py', 'node_main.py', 'ros_tools/*', 'cli/*'},
    'visibility_builder': {'builder_node.py'},
    'landmark_localizer': {'node.py', 'node_frames.py', 'conversions.py'},
    'landmark_db': set(),
    'vbn_worlds': set(),
    'vbn_bench': set(),
}
#: rosdep keys of the third-party modules the packages import (None: pip only, no key;
#: installed by requirements.txt).
KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'cv2': 'python3-opencv',
    'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm',
    'rosbags': 'python3-rosbags-pip', 'mcap': 'mcap-ros2-support', 'rclpy': 'rclpy',
    'ament_index_python': 'ament_index_python', 'skimage': 'python3-skimage',
    'ruamel': 'python3-ruamel.yaml', 'numba': 'python3-numba',
    'lz4': None, 'zstandard': None,   # rosbags' own dependencies (python3-rosbags-pip)
    'evo': None,            # the localizer's benchmark: evo_ape beside our accuracy
    'pycolmap': None,       # the benchmark's structure-based peer (requirements.txt pins it)
    'gtsam': 'gtsam',       # the bundle adjustment of vbn estimate-poses
    'backports': None,      # backports.zstd (the zstd of Python 3.14 before 3.14)
    'compression': None,    # Python 3.14's standard library
}
#: Declared without a static import: message packages that the bag tools load by type name
#: (``vbn play``, ``record`` and ``echo`` of the sample bags).
BY_TYPE_NAME = {'vbn_common': {'sensor_msgs', 'nav_msgs', 'diagnostic_msgs'}}
MAX_LINES = 600


def _sources(package: str) -> list[Path]:
    return sorted((SRC / package / package).rglob('*.py'))


def _imports(path: Path) -> set[str]:
    """Every absolute module an ``import``/``from`` statement names, anywhere in the file."""
    modules: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            modules.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            modules.add(node.module)
    return modules


def _is_ros(module: str) -> bool:
    top = module.split('.')[0]
    return top == 'rclpy' or top.endswith(('_msgs', '_srvs', '_interfaces'))


def _is_glue(package: str, path: Path) -> bool:
    rel = path.relative_to(SRC / package / package).as_posix()
    return any(rel == g or (g.endswith('/*') and rel.startswith(g[:-1]))
               for g in GLUE[package])


@pytest.mark.parametrize('package', PROJECT)
def test_packages_import_only_the_packages_below_them(package: str) -> None:
    offenders = []
    for path in _sources(package):
        for module in _imports(path):
            top = module.split('.')[0]
            if top in PROJECT and top != package and top not in ALLOWED[package]:
                offenders.append(f'{path.relative_to(SRC)}: {module}')
    assert offenders == []


@pytest.mark.parametrize('package', PROJECT)
def test_rclpy_and_messages_only_in_the_ros_glue(package: str) -> None:
    offenders = [f'{path.relative_to(SRC)}: {module}'
                 for path in _sources(package) if not _is_glue(package, path)
                 for module in _imports(path) if _is_ros(module)]
    assert offenders == []


def test_the_glue_list_names_real_modules() -> None:
    for package, globs in GLUE.items():
        for pattern in globs:
            target = SRC / package / package / pattern.rstrip('/*')
            assert target.exists(), f'{package}: {pattern}'


@pytest.mark.parametrize('package', PROJECT)
def test_no_source_file_is_over_600_lines(package: str) -> None:
    long = {str(p.relative_to(SRC)): n for p in _sources(package)
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def _declared(package: str) -> set[str]:
    root = ET.parse(SRC / package / 'package.xml').getroot()
    return {e.text for tag in ('depend', 'exec_depend') for e in root.findall(tag)}


def _needed(package: str) -> set[str]:
    needed: set[str] = set()
    for path in _sources(package):
        for module in _imports(path):
            top = module.split('.')[0]
            if top == package or top in sys.stdlib_module_names or top == '__future__':
                continue
            if top in PROJECT or _is_ros(module):
                needed.add(top)
                continue
            assert top in KEYS, f'{path.relative_to(SRC)} imports {top}: give it a rosdep key'
            if KEYS[top]:
                needed.add(KEYS[top])
    return needed


@pytest.mark.parametrize('package', PROJECT)
def test_package_xml_declares_what_the_package_imports(package: str) -> None:
    declared, needed = _declared(package), _needed(package) | BY_TYPE_NAME.get(package, set())
    assert sorted(needed - declared) == [], 'imported but not declared'
    assert sorted(declared - needed) == [], 'declared but not imported'


@pytest.mark.parametrize('package', RUNTIME)
def test_the_runtime_packages_import_no_benchmark_library(package: str) -> None:
    offenders = [f'{path.relative_to(SRC)}: {module}' for path in _sources(package)
                 for module in _imports(path) if module.split('.')[0] in BENCH_ONLY]
    assert offenders == []


def _command_lines(text: str) -> list[int]:
    """Lines that start ``vbn`` or a ``python -m`` of one of our modules as a process."""
    return [number for number, line in enumerate(text.splitlines(), 1)
            if ("'-m'" in line and any(f"'{p}." in line for p in PROJECT))
            or any(f"{opening}'vbn'" in line for opening in '[(,')]


#: The one module that names the processes of a ROS graph (the bag tools over DDS, the
#: probe's echo): a DDS exchange between processes needs processes.
GRAPH_PROCESSES = SRC / 'vbn_common' / 'vbn_common' / 'graph_processes.py'


@pytest.mark.parametrize('package', PROJECT)
def test_no_code_runs_our_own_commands_as_subprocesses(package: str) -> None:
    hits = [f'{path.relative_to(SRC)}:{number}' for path in _sources(package)
            if path != GRAPH_PROCESSES for number in _command_lines(path.read_text())]
    assert hits == []


def test_the_graph_processes_are_the_bag_tools_and_the_probe() -> None:
    from vbn_common import graph_processes as graph

    assert set(graph.GRAPH_PROCESSES) == {'play', 'record', 'dds_probe'}


def test_the_subprocess_rule_catches_a_command() -> None:
    assert _command_lines("x = 1\nrun([sys.executable, '-m', 'vbn_common.cli.main'])\n") == [2]
    assert _command_lines("subprocess.run(['vbn', 'build', bag])\n") == [1]
    assert _command_lines("subprocess.run([sys.executable, '-c', 'while True: pass'])\n") == []


def _test_imports(package: str) -> set[str]:
    """The other project packages that the package's tests import."""
    return {module.split('.')[0] for path in sorted((SRC / package / 'test').rglob('*.py'))
            for module in _imports(path)} & set(PROJECT) - {package}


@pytest.mark.parametrize('package', PROJECT)
def test_package_xml_declares_no_project_package_for_the_tests(package: str) -> None:
    # colcon orders packages by their test dependencies too, and a test of a lower package
    # that renders a world or builds a database (vbn_common's tests import landmark_db,
    # the localizer's the builder and the benchmarks) would make the order a cycle: the
    # tests run in the whole built workspace instead, and a package's own code keeps the
    # rules above.
    root = ET.parse(SRC / package / 'package.xml').getroot()
    assert {e.text for e in root.findall('test_depend')} & set(PROJECT) == set()


def test_some_tests_do_stand_on_higher_packages() -> None:
    # Why the rule above is needed: without it colcon would find a cycle.
    assert 'landmark_db' in _test_imports('vbn_common')
    assert 'visibility_builder' in _test_imports('landmark_localizer')


def test_the_rules_catch_a_wrong_import(tmp_path: Path) -> None:
    bad = tmp_path / 'bad.py'
    bad.write_text('import rclpy\nfrom visibility_builder.build import build\n')
    assert _imports(bad) == {'rclpy', 'visibility_builder.build'}
    assert _is_ros('rclpy.node') and _is_ros('std_srvs.srv') and not _is_ros('numpy')
