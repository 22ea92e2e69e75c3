"""Install the vbn_bench package (ament_python)."""
from setuptools import find_packages, setup

package_name = 'vbn_bench'

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
    description='Every benchmark, the demo, the offline localization and its evaluation, '
                'the full-feature baseline and the structure-based peer.',
    license='Apache-2.0',
    entry_points={
        'vbn.commands': [
            'bench-decomposition = vbn_bench.cli.bench_decomposition:register',
            'bench-build = vbn_bench.cli.bench_build:register',
            'bench-estimate = vbn_bench.cli.bench_estimate:register',
            'bench-strecha = vbn_bench.cli.bench_strecha:register',
            'localize = vbn_bench.cli.localize:register',
            'bench-localize = vbn_bench.cli.bench_localize:register',
            'bench-integrity = vbn_bench.cli.bench_integrity:register',
            'demo = vbn_bench.cli.demo:register',
        ],
    },
)
