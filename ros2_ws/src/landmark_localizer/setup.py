"""Install the landmark_localizer package (ament_python)."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'landmark_localizer'

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
    description='Runtime view-based localizer over the landmark database.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'localizer = landmark_localizer.main:main',
        ],
    },
)
