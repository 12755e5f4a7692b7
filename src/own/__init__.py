"""The project's own broad phases: compiled (numba) exact algorithms and the essay's Python ones."""
