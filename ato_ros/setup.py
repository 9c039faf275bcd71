from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_ros'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={PACKAGE_NAME: ['fastdds_profile.xml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        "The rclpy edge of the ATO emulator: QoS profiles and message conversion, the nodes' "
        'start-up and teardown, validated parameters, the wire encoding of the standard '
        'messages, the step records for the recorders and the middleware settings.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'hypothesis', 'numpy'],
    entry_points={
        'console_scripts': [],
    },
)
