from glob import glob

from setuptools import find_packages, setup

package_name = 'rfi_experiments'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.xml')),
        ('share/' + package_name + '/scenarios', glob('scenarios/*.yaml')),
        ('share/' + package_name + '/viz', glob('viz/*.json') + glob('viz/*.rviz')),
        ('share/' + package_name + '/data', sorted(glob('data/*.1[0-9][no]')) + ['data/README.md']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rfi suite maintainers',
    maintainer_email='maintainers@example.com',
    description='Jamming experiments: simulate, play, record, replay, evaluate.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'play = rfi_experiments.play:cli',
            'record = rfi_experiments.record:cli',
            'run = rfi_experiments.run:main',
            'simulate = rfi_experiments.simulate:main',
            'rinex_to_bag = rfi_experiments.rinex_to_bag:main',
            'uwb_dataset_to_bag = rfi_experiments.uwb_dataset_to_bag:main',
            'ubx_source = rfi_experiments.ubx_source:main',
            'ubx_to_bag = rfi_experiments.ubx_to_bag:main',
            'if_source = rfi_experiments.if_source:main',
            'if_to_bag = rfi_experiments.if_to_bag:main',
        ],
    },
)
