from setuptools import find_packages, setup

PACKAGE_NAME = 'profile_node'

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
        'Distance-to-go target curve: builds a smooth, jerk-limited, time-parameterised reference'
        ' from a line description and streams it.'
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'numpy', 'PyYAML', 'grimp'],
    entry_points={
        'console_scripts': [
            'profile_node = profile_node.entry:main'
        ],
    },
)
