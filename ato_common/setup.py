from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_common'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'ato_common': ['scenarios/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'The domain model of the ATO emulator, without ROS: SI units and paper-unit '
        'conversions, train presets, lines, scenarios and TTOBench files, braking curves and '
        "supervision tables, uncertainty, the controller's knowledge of its train, tracking "
        'metrics, and the interface conventions (topic names, QoS as data).'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'hypothesis', 'numpy', 'PyYAML'],
    entry_points={
        'console_scripts': [
            'scenario_from_ttobench = ato_common.scenario_from_ttobench:main',
        ],
    },
)
