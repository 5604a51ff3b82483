from glob import glob

from setuptools import find_packages, setup

package_name = 'gnss_correlator'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.xml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rfi suite maintainers',
    maintainer_email='maintainers@example.com',
    description='GPS L1 C/A acquisition and tracking on front-end IF samples: the correlators of imm_carrier.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'gnss_correlator_node = gnss_correlator.gnss_correlator_node:main',
        ],
    },
)
