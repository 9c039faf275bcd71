from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_simulation'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={PACKAGE_NAME: []},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'The closed loop of the ATO emulator without ROS: the plant, profile and controller '
        "cores stepped in the lockstep graph's order, and the plan cache that the offline runs "
        "and the graph's runner share."
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'numpy', 'PyYAML'],
    entry_points={
        'console_scripts': ['run_offline = ato_simulation.run_offline:main'],
    },
)
