import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_bringup'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        (os.path.join('share', PACKAGE_NAME, 'launch'), glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'Bring-up of the ATO emulator: the launch file, the scenario runner that starts the '
        'stack, drives it to the end of a scenario and prints the run summary, the composed '
        'stack (the three loop nodes in one process), the ato command line and the conformance '
        'harness for an ATO node of your own.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'PyYAML', 'numpy'],
    entry_points={
        'console_scripts': [
            'run_scenario = ato_bringup.run_scenario:main',
            'run_offline = ato_simulation.run_offline:main',
            'campaign = ato_campaigns.campaign:main',
            'ato_stack = ato_bringup.composed:main',
            'conformance = ato_bringup.conformance:main',
            'scorecard = ato_bringup.scorecard:main',
        ],
    },
)
