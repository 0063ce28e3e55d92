"""Preload of the local Dask workers that `mocapkit.pipelines.batch` starts.

Ctrl-C at a terminal reaches the whole process group: the batch's own process, which
stops the cluster and says what finished, and every worker process, each of which would
print its traceback. Loaded in each worker process as it starts (Dask's ``preload``),
this module makes the worker ignore SIGINT; the batch stops it.
"""

from __future__ import annotations

import signal
import threading
from typing import Any


def dask_setup(worker: Any = None) -> None:
    """Ignore SIGINT in this worker process (called by Dask as the worker starts)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


__all__ = ["dask_setup"]
