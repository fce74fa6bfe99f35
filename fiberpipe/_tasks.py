"""How many ``prange`` tasks a parallel pass splits its items into (a leaf module)."""

from __future__ import annotations

from numba import njit

# tasks of a scatter split by nodes (the contact and friction passes' forces onto the nodes, each
# task adding those on its share of the nodes in pair order): each task reads every pair's row, so
# more than two cost more reading than they save in adding
SCATTER_TASKS = 2


@njit(cache=True)
def task_count(n_items, min_items, max_tasks):
    """Tasks for ``n_items`` items: at least ``min_items`` items each, at most ``max_tasks``, rounded
    down to a power of two (1: a serial pass).

    numba gives each thread an equal share of a parallel loop's tasks up front, so 5 tasks on 2
    threads run as 3 against 2: the pass takes 3/5 of its serial time at best, 4 tasks take 1/2. A
    power of two is a multiple of 1, 2, 4 or 8 threads once there are enough tasks for each; the
    count is fixed without asking numba for its threads, which a cached step loop cannot do (the
    call reads a ctypes pointer)."""
    n = min(max_tasks, n_items // min_items)
    p = 1
    while 2 * p <= n:
        p *= 2
    return p
