"""Job logging for workflow scripts."""

from __future__ import annotations

import os
import sys
from typing import TextIO


def log_to(path: str) -> TextIO:
    """Send everything the job prints to ``path``: Python output, tracebacks, and native
    libraries (FFmpeg) writing to file descriptors 1 and 2. Returns the open log file, which
    stays open so that a traceback at exit lands in it too."""
    log = open(path, "w", buffering=1)  # noqa: SIM115 - must outlive the caller's scope
    os.dup2(log.fileno(), 1)
    os.dup2(log.fileno(), 2)
    sys.stdout = sys.stderr = log
    return log
