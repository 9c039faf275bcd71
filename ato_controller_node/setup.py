from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_controller_node'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # the tuned gains (ato_controller_node.gains): one artefact per train and law
    package_data={PACKAGE_NAME: ['tuned/*/*.json']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        'Automatic train operation controller: runs the control law selected by a parameter from '
        'its registry of laws at a fixed rate.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'hypothesis', 'numpy', 'scipy'],
    entry_points={
        'console_scripts': [
            'ato_controller_node = ato_controller_node.entry:main'
        ],
    },
)
