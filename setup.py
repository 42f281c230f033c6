# Stub for colcon (ament_python needs a setup.py); the configuration is in pyproject.toml
# and setup.cfg.
from setuptools import setup

setup()
