"""Install the vbn_worlds package (ament_python)."""
from setuptools import find_packages, setup

package_name = 'vbn_worlds'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='View-based navigation maintainers',
    maintainer_email='maintainers@view-based-navigation.invalid',
    description='Rendered worlds for tests and benchmarks: the 2.5-D renderer, bag synthesis '
                'and the Chapter 8 simulator of random worlds.',
    license='Apache-2.0',
    entry_points={
        'vbn.commands': [
            'render = vbn_worlds.cli.render:register',
            'simulate = vbn_worlds.cli.simulate:register',
        ],
    },
)
