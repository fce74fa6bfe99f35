"""The task counts of the parallel passes: multiples of the running threads."""

import numba
import pytest

from fiberpipe._tasks import task_count


def test_one_thread_takes_the_items_per_task_and_the_cap():
    if numba.config.NUMBA_NUM_THREADS < 1:
        pytest.skip("no numba threads")
    numba.set_num_threads(1)
    assert task_count(5 * 32, 32, 8) == 5
    assert task_count(1000, 32, 8) == 8
    assert task_count(10, 32, 8) == 1


def test_tasks_are_a_multiple_of_the_threads_once_each_thread_gets_one():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs NUMBA_NUM_THREADS >= 2")
    numba.set_num_threads(2)
    try:
        assert task_count(5 * 32, 32, 8) == 4   # 5 would run as 3 against 2
        assert task_count(3 * 32, 32, 8) == 2
        assert task_count(2 * 32, 32, 8) == 2
        assert task_count(32, 32, 8) == 1       # one task: the serial pass
        assert task_count(1000, 32, 7) == 6
    finally:
        numba.set_num_threads(1)
