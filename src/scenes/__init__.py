"""Scenes shared by tests, studies and pictures: generators, motion, and scene files."""

from .generate import DISTRIBUTIONS, ESSAY_COVERAGE, coverage, generate
from .scene import ESSAY_BOX, Scene

__all__ = ["DISTRIBUTIONS", "ESSAY_BOX", "ESSAY_COVERAGE", "Scene", "coverage", "generate"]
