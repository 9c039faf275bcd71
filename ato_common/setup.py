from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_common'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'ato_common': ['scenarios/*.yaml', 'fastdds_profile.xml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'Shared conventions of the ATO emulator: topic names, QoS, SI units and paper-unit '
        'conversions, message conversion, train presets, line descriptions and scenarios.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'hypothesis', 'numpy', 'PyYAML'],
    entry_points={
        'console_scripts': [
            'scenario_from_ttobench = ato_common.scenario_from_ttobench:main',
        ],
    },
)
