from glob import glob

from setuptools import find_packages, setup

package_name = 'intersection_estimator'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=['intersection_estimator', 'intersection_estimator.*',
                                    'msg_adapters', 'msg_adapters.*']),
    package_data={'msg_adapters': ['schemas/*.msg', 'schemas/**/*.msg']},
    include_package_data=True,
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/bags', glob('bags/*.json') + glob('bags/*.md')),
    ] + [('share/' + package_name + '/' + d, glob(d + '/*')) for d in sorted(glob('bags/*/'))],
    install_requires=['setuptools'],
    # map-change detection on a Ray cluster (intersection-estimator fleet --engine ray)
    extras_require={'fleet': ['ray==2.60.0']},
    zip_safe=False,
    maintainer='intersection_estimator developers',
    maintainer_email='dev@intersection-estimator.invalid',
    description='Map-free lane-level intersection estimation from observed traffic (Meyer et al., ITSC 2019).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'intersection_estimator_node = intersection_estimator.node:main',
            'intersection_estimator_lifecycle_node = intersection_estimator.node_lifecycle:main',
            'intersection-estimator = intersection_estimator.cli:main',
        ],
    },
)
