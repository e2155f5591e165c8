"""ament_python package hyst_model; `colcon build` and `pip install -e` both accept it."""
from setuptools import find_packages, setup

package_name = 'hyst_model'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    package_data={'hyst_model': ['data/*.yaml', 'data/*.md']},
    install_requires=['numpy', 'scipy', 'numba', 'pyyaml', 'rosbags', 'mcap', 'mcap-ros2-support', 'matplotlib'],
    zip_safe=True,
    maintainer='hyst developers',
    maintainer_email='hyst@example.org',
    description=('Hysteresis models (backlash, Dahl, Bouc-Wen, MBW, Prandtl-Ishlinskii), physical-effect extensions, '
                 'identification (EPSO, fast fitter), residual diagnostics, bag/CSV IO and the hyst command line.'),
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'hyst = hyst_model.cli.main:main',
            'hyst_ident_node = hyst_model.ident_node:main',
            'hyst_residual_node = hyst_model.residual_node:main',
        ],
    },
)
