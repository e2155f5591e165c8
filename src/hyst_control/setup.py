"""ament_python package hyst_control; `colcon build` and `pip install -e` both accept it."""
from setuptools import find_packages, setup

package_name = 'hyst_control'

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
    description=('DPPC, DMRAC and PID controllers for hysteretic actuators, a controller node that switches algorithm '
                 'while running, and a reference generator.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'hyst_controller_node = hyst_control.controller_node:main',
            'hyst_reference_node = hyst_control.reference_node:main',
            'hyst_excite_node = hyst_control.excite_node:main',
        ],
        'hyst.commands': [
            'excite = hyst_control.cli_excite:register',
        ],
    },
)
