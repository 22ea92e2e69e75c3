"""Install the visibility_builder package (ament_python)."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'visibility_builder'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='View-based navigation maintainers',
    maintainer_email='maintainers@view-based-navigation.invalid',
    description='Offline builder of the landmark database and renderer of sample bags.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'builder = visibility_builder.main:main',
        ],
        'vbn.commands': [
            'build = visibility_builder.cli.build:register',
            'estimate-poses = visibility_builder.cli.estimate_poses:register',
            'db-update = visibility_builder.cli.db_update:register',
        ],
    },
)
