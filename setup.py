# The Python package of rover_loop_fusion (scripts/roverlib: scenarios, evaluation, benchmark
# plumbing), installed by catkin_python_setup() in CMakeLists.txt: after sourcing the
# workspace's devel/setup.bash (scripts/setup.sh does) `import roverlib` works from anywhere.
# Not for pip: catkin calls it.
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=["roverlib"], package_dir={"": "scripts"}))
