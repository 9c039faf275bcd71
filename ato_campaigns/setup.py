from setuptools import find_packages, setup

PACKAGE_NAME = 'ato_campaigns'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={PACKAGE_NAME: ['campaigns/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='ATO emulator maintainers',
    maintainer_email='ato-emulator@example.org',
    description=(
        "Comparisons and robustness campaigns of the ATO emulator's control laws: the campaign "
        'engine on Dask, its statistics and reports, the comparison of every law on every '
        "scenario, the worker's run process and the provenance of the results pages."
    ),
    license='Apache-2.0',
    tests_require=['pytest', 'numpy', 'scipy', 'PyYAML', 'pandas', 'distributed'],
    entry_points={
        'console_scripts': [
            'campaign = ato_campaigns.campaign:main',
            'compare = ato_campaigns.compare:main',
        ],
    },
)
