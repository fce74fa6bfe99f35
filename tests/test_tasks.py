"""The task counts of the parallel passes: powers of two, so a multiple of the running threads."""

from fiberpipe._tasks import task_count


def test_tasks_take_the_items_per_task_and_the_cap():
    assert task_count(8 * 32, 32, 8) == 8
    assert task_count(1000, 32, 8) == 8
    assert task_count(2 * 32, 32, 8) == 2
    assert task_count(32, 32, 8) == 1   # one task: the serial pass
    assert task_count(10, 32, 8) == 1


def test_tasks_are_a_power_of_two():
    """5 tasks would run as 3 against 2 on two threads; 4 split evenly on 1, 2 or 4."""
    assert task_count(5 * 32, 32, 8) == 4
    assert task_count(3 * 32, 32, 8) == 2
    assert task_count(7 * 32 + 31, 32, 8) == 4
    assert task_count(1000, 32, 6) == 4
