from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'recorder'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        ('share/' + PACKAGE_NAME + '/config', glob('config/*.json')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        "Records the ATO emulator's topics to MCAP in the rosbag2 conventions (raw CDR, full "
        'ros2msg schemas, offered QoS, metadata.yaml), replays recordings with their timing and '
        "/clock, recovers killed recordings, reports a run's metrics and plots from its "
        'recording, and serves the running graph to Foxglove live.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'PyYAML', 'mcap', 'mcap-ros2-support', 'rosbags', 'tornado'],
    entry_points={
        'console_scripts': [
            'recorder = recorder.node:main',
            'replay = recorder.replay:main',
            'info = recorder.cli:info_main',
            'recover = recorder.cli:recover_main',
            'report = recorder.report:main',
            'live = recorder.live:main',
        ],
    },
)
