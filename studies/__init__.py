"""Runnable experiments: `python -m studies.compare`, and the shared harness they use."""
