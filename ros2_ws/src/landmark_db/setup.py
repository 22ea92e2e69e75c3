"""Install the landmark_db package (ament_python)."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'landmark_db'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'landmark_db.scenes': ['*.json']},
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
    description='World instances, region decomposition (rho-MORDP) and the landmark database.',
    license='Apache-2.0',
    entry_points={
        'vbn.commands': [
            'decompose = landmark_db.cli.decompose:register',
            'validate = landmark_db.cli.validate:register',
            'db-info = landmark_db.cli.db_info:register',
            'db-export = landmark_db.cli.db_export:register',
        ],
    },
)
