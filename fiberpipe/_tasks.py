"""How many ``prange`` tasks a parallel pass splits its items into (a leaf module)."""

from __future__ import annotations

import numba
from numba import njit


@njit(cache=False)  # numba.get_num_threads reads a ctypes pointer: no disk cache
def task_count(n_items, min_items, max_tasks):
    """Tasks for ``n_items`` items: at least ``min_items`` items each, at most ``max_tasks``, and a
    multiple of the running threads once there are enough for each thread to get one (1: a serial pass).

    numba gives each thread an equal share of a parallel loop's tasks up front, so 5 tasks on 2
    threads run as 3 against 2: the pass takes 3/5 of its serial time at best, 4 tasks take 1/2."""
    n = min(max_tasks, n_items // min_items)
    threads = numba.get_num_threads()
    if n >= threads > 1:
        n -= n % threads
    return max(n, 1)
