"""Install the vbn_common package (ament_python)."""
from setuptools import find_packages, setup

package_name = 'vbn_common'

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
    description='Bags, images, SIFT, the exploration reader, camera models and two-view '
                'geometry, and the ROS glue that the builder and the localizer share.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'vbn = vbn_common.cli.main:main',
            'dds_probe = vbn_common.dds_probe_main:main',
        ],
        'vbn.commands': [
            'doctor = vbn_common.cli.doctor:register',
            'bag-info = vbn_common.cli.bag_info:register',
            'echo = vbn_common.cli.echo:register',
            'play = vbn_common.cli.play:register',
            'record = vbn_common.cli.record:register',
        ],
    },
)
