"""ament_python package hyst_bringup; `colcon build` and `pip install -e` both accept it."""
from setuptools import find_packages, setup

package_name = 'hyst_bringup'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['numpy'],
    zip_safe=True,
    maintainer='hyst developers',
    maintainer_email='hyst@example.org',
    description=('The top of hyst: the device emulator on the simulated plant, the in-process closed loop (hyst '
                 'track), the single-process 2 kHz loop node and hyst demo.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'hyst_emulator = hyst_bringup.emulator:main',
            'hyst_loop_node = hyst_bringup.composed:main',
        ],
        'hyst.commands': [
            'track = hyst_bringup.cli_track:register',
            'demo = hyst_bringup.demo:register',
        ],
    },
)
