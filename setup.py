# The Python package of rover_loop_fusion (scripts/roverlib: scenarios, evaluation, benchmark
# plumbing), installed twice from this one file:
#   - by catkin_python_setup() in CMakeLists.txt: after sourcing the workspace's
#     devel/setup.bash (scripts/setup.sh does) `import roverlib` works in /usr/bin/python3
#     (the demo, rosrun, the rostests; the install space too);
#   - into the venv by scripts/venv.sh (pip install --no-build-isolation -e ., editable): the
#     venv's Python (tests, benchmarks) imports it without the workspace.
# No program or test adds a directory to the import path (test/python/test_packaging.py).
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=["roverlib"], package_dir={"": "scripts"}))
