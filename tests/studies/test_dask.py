"""The Dask path of ``fiberpipe study``: a local Dask cluster (``--workers`` > 1) and an existing
scheduler (``--scheduler ADDRESS``) give the same results as the local process pool.

Dask is in the ``test`` extra (``pip install -e '.[test]'``); without it these tests are skipped.
"""

import csv
import sys

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from fiberpipe.errors import ConfigError
from fiberpipe.studies.sweep import run_study

distributed = pytest.importorskip("dask.distributed")

# the cheapest scene and study of test_sweep.py, with two workers
from test_sweep import BASE, STUDY as _STUDY  # noqa: E402  (same folder, on sys.path under pytest)

STUDY = _STUDY + "workers: 2\n"

TIMING = {"wall_time_s", "element_steps_per_s"}  # differ from run to run


def _study(tmp_path):
    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY)
    return tmp_path / "study.yaml"


def _rows(out):
    return [{k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader((out / "study.csv").open())]


def _float_datasets(out, pid):
    """Every float dataset of a point's simulation.h5 (positions, history...) but wall times."""
    with h5py.File(out / "points" / pid / "simulation.h5", "r") as f:
        return {k: np.asarray(v) for k, v in _datasets(f)}


def _datasets(group, prefix=""):
    for name, item in group.items():
        if isinstance(item, h5py.Dataset):
            if item.dtype.kind == "f" and "wall" not in name:
                yield prefix + name, item[()]
        else:
            yield from _datasets(item, prefix + name + "/")


@pytest.fixture(scope="module")
def pool_run(tmp_path_factory):
    """The study run one point after the other in this process, then on the local process pool
    (Dask hidden): the baseline, and a check of the pool against the serial path. The serial run
    first loads the kernels, so the forked pool workers do not load them again."""
    tmp = tmp_path_factory.mktemp("pool")
    study = _study(tmp)
    serial = run_study(study, tmp / "serial", workers=1, echo=lambda s: None)
    lines = []
    mp = pytest.MonkeyPatch()
    mp.setitem(sys.modules, "dask.distributed", None)  # `from dask.distributed import ...` fails
    try:
        out = run_study(study, tmp / "pool", echo=lines.append)
    finally:
        mp.undo()
    assert any("local process pool (2 processes; Dask not installed)" in s for s in lines)
    _assert_same(out, serial)
    return out


def _assert_same(out, base):
    rows, ref_rows = _rows(out), _rows(base)
    assert rows == ref_rows  # errors, steps, ids: identical (same code, one numba thread)
    assert [r["solver.dt_safety"] for r in rows] == ["0.5", "0.9"]
    assert all(0 < float(r["position_error"]) < 1e-2 for r in rows)
    for r in rows:
        a, b = _float_datasets(out, r["id"]), _float_datasets(base, r["id"])
        assert a.keys() == b.keys() and a
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


class _InProcessCluster(distributed.LocalCluster):
    """The LocalCluster ``fiberpipe study --workers N`` starts, with its workers in threads of this
    process (no worker start-up, no kernel loading); records the instances to check they close."""

    made = []

    def __init__(self, *args, **kwargs):
        self.fiberpipe_kwargs = dict(kwargs)
        kwargs.update(processes=False, n_workers=1, dashboard_address=None)
        kwargs.pop("env", None)
        super().__init__(*args, **kwargs)
        _InProcessCluster.made.append(self)


def test_local_dask_cluster_matches_process_pool(tmp_path, pool_run, monkeypatch):
    import dask.distributed

    monkeypatch.setattr(dask.distributed, "LocalCluster", _InProcessCluster)
    _InProcessCluster.made.clear()
    lines = []
    out = run_study(_study(tmp_path), tmp_path / "out", echo=lines.append)
    assert any("local Dask cluster (2 worker processes)" in s for s in lines)
    (cluster,) = _InProcessCluster.made
    assert cluster.fiberpipe_kwargs == {"n_workers": 2, "threads_per_worker": 1, "processes": True, "env": {"NUMBA_NUM_THREADS": "1"}}
    assert cluster.status.name == "closed"  # the study closes the cluster it started
    _assert_same(out, pool_run)


@pytest.mark.slow  # 13–18 s: two worker processes start, import fiberpipe and load the kernels (make test-all)
def test_local_dask_cluster_with_worker_processes_matches_process_pool(tmp_path, pool_run):
    lines = []
    out = run_study(_study(tmp_path), tmp_path / "out", echo=lines.append)
    assert any("local Dask cluster (2 worker processes)" in s for s in lines)
    _assert_same(out, pool_run)


def test_existing_scheduler_via_cli_matches_process_pool(tmp_path, pool_run):
    from fiberpipe.cli import main

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        res = CliRunner().invoke(main, ["study", str(_study(tmp_path)), "--out", str(tmp_path / "out"),
                                        "--scheduler", cluster.scheduler_address])
        assert res.exit_code == 0, res.output + repr(res.exception)
        assert f"on the Dask scheduler {cluster.scheduler_address}" in res.output
        # the reference and both points ran on that cluster's (in-process) worker
        (worker,) = cluster.workers.values()
        assert worker.state.executed_count == 3
        assert cluster.status.name == "running"  # a scheduler the study did not start stays up
    _assert_same(tmp_path / "out", pool_run)


def test_scheduler_without_dask_is_a_config_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(ConfigError, match="needs Dask"):
        run_study(_study(tmp_path), tmp_path / "out", scheduler="tcp://127.0.0.1:1", echo=lambda s: None)
    assert not any((tmp_path / "out" / "points").iterdir())
