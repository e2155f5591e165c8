"""ament_python package hyst_driver; `colcon build` and `pip install -e` both accept it."""
from setuptools import find_packages, setup

package_name = 'hyst_driver'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['numpy', 'pyserial'],
    zip_safe=True,
    maintainer='hyst developers',
    maintainer_email='hyst@example.org',
    description=('Serial driver node for the PEA/GMA amplifier and displacement sensor, protocol adapters and a device '
                 'emulator.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'hyst_driver_node = hyst_driver.driver_node:main',
        ],
    },
)
