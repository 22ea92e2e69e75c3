"""The colcon workspace is laid out so that ros2 run finds every executable."""
from __future__ import annotations

import xml.etree.ElementTree as ET

from paths import REPO
import pytest

ROOT = REPO
WS = ROOT / 'ros2_ws'
PACKAGES = ('vbn_common', 'landmark_db', 'visibility_builder', 'landmark_localizer',
            'vbn_worlds', 'vbn_bench')
EXECUTABLES = {'vbn_common': ['vbn', 'dds_probe'],
               'visibility_builder': ['builder'], 'landmark_localizer': ['localizer']}


@pytest.mark.parametrize('package', PACKAGES)
def test_package_manifest_is_format_3_ament_python(package):
    root = ET.parse(WS / 'src' / package / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == package
    assert root.find('export/build_type').text == 'ament_python'
    assert (WS / 'src' / package / 'resource' / package).is_file()
    setup_cfg = (WS / 'src' / package / 'setup.cfg').read_text()
    assert f'install_scripts=$base/lib/{package}' in setup_cfg


@pytest.mark.parametrize('package', PACKAGES)
def test_colcon_installed_the_package_into_the_ament_index(package):
    marker = WS / 'install' / package / 'share' / 'ament_index' / 'resource_index' / 'packages'
    assert (marker / package).is_file()
    assert (WS / 'install' / package / 'share' / package / 'package.xml').is_file()


@pytest.mark.parametrize(('package', 'name'),
                         [(p, e) for p, names in EXECUTABLES.items() for e in names])
def test_executables_are_in_lib_package(package, name):
    exe = WS / 'install' / package / 'lib' / package / name
    assert exe.is_file()
    assert exe.stat().st_mode & 0o111


@pytest.mark.parametrize('package', PACKAGES)
def test_colcon_test_finds_the_package_tests(package):
    # colcon runs pytest in a package's folder when setup.py names pytest in tests_require
    # (and package.xml as a test_depend); the tests are in its test/ folder.
    assert "tests_require=['pytest']" in (WS / 'src' / package / 'setup.py').read_text()
    root = ET.parse(WS / 'src' / package / 'package.xml').getroot()
    assert 'python3-pytest' in {e.text for e in root.findall('test_depend')}
    assert list((WS / 'src' / package / 'test').glob('test_*.py'))
