"""Build hook: setuptools reads pyproject.toml; C extensions of the twin's core are declared here."""

from setuptools import setup

setup()
