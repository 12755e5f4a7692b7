"""Scenes shared by tests, studies and pictures: generators, motion, and scene files."""

from .families import FAMILIES
from .generate import DISTRIBUTIONS, ESSAY_COVERAGE, SCENE_KINDS, coverage, generate
from .scene import ESSAY_BOX, Scene

__all__ = ["DISTRIBUTIONS", "ESSAY_BOX", "ESSAY_COVERAGE", "FAMILIES", "SCENE_KINDS", "Scene", "coverage", "generate"]
