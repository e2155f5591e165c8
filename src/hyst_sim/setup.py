"""ament_python package hyst_sim; `colcon build` and `pip install -e` both accept it."""
from setuptools import find_packages, setup

package_name = 'hyst_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    package_data={'hyst_sim': ['data/*.yaml', 'data/*.md', 'data/scenarios/*.yaml']},
    install_requires=['numpy'],
    zip_safe=True,
    maintainer='hyst developers',
    maintainer_email='hyst@example.org',
    description=('Simulated actuator stage that stands in for the driver: MBW plant with optional hidden physical '
                 'effects; bag recorder and player.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'hyst_sim_node = hyst_sim.sim_node:main',
            'hyst_bag_record = hyst_sim.record_node:main',
            'hyst_bag_play = hyst_sim.play_node:main',
        ],
    },
)
