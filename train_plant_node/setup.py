from setuptools import find_packages, setup

PACKAGE_NAME = 'train_plant_node'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'Train plant simulator: longitudinal train dynamics with Davis resistance and line '
        'forces, actuator limits, failures, sensors, ATP supervision, truth and measured state, '
        'lockstep simulated time.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'numpy'],
    entry_points={
        'console_scripts': [
            'train_plant_node = train_plant_node.entry:main'
        ],
    },
)
