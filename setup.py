from setuptools import find_packages, setup

package_name = 'rbe_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['tests', 'tests.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    # Python dependencies are pinned in requirements/*.txt (scripts/setup.sh) or come from
    # the ROS install (package.xml); none are declared here so that colcon and
    # `pip install -e . --no-deps` behave the same.
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='rbe_ros maintainers',
    maintainer_email='rbe-ros@example.com',
    description='Rigid-block equilibrium checks of block assemblies as a ROS 2 node and CLI.',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'rbe_node = rbe_ros.ros.node:main',
            'rbe_lifecycle_node = rbe_ros.ros.lifecycle_node:main',
            'rbe-ros = rbe_ros.cli:main',
        ],
    },
)
