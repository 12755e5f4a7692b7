"""Scenes shared by tests, studies and pictures: generators, motion, and scene files."""

from .generate import DISTRIBUTIONS, generate
from .scene import ESSAY_BOX, Scene

__all__ = ["DISTRIBUTIONS", "ESSAY_BOX", "Scene", "generate"]
