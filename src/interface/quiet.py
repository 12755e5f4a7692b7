"""Silence what a native library prints on its own (build banners, driver probes), so that the
studies' tables and logs stay readable. Python exceptions still pass through."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys


@contextlib.contextmanager
def native_output_silenced():
    """Send file descriptors 1 and 2 to /dev/null for the duration, C-level writes included."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    devnull = os.open(os.devnull, os.O_WRONLY)
    for fd in saved:
        os.dup2(devnull, fd)
    try:
        yield
    finally:
        ctypes.CDLL(None).fflush(None)  # C buffers its output when it is not a terminal
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)
