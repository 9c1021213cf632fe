"""``interprim evaluate --backend dask --scheduler ADDRESS`` runs the sweep on an existing Dask cluster and gives
the serial backend's numbers.

The cluster is a real ``distributed.LocalCluster`` of two single-threaded worker processes reached over TCP,
started and closed here.  Two threads in total are needed: joblib runs the jobs in the calling process when
the cluster has one thread (its effective ``n_jobs`` is then 1), which would test nothing.  Worker
*processes* rather than threads of this process: every fold limits BLAS to one thread with
``threadpoolctl``, a process-wide setting that two folds in two threads of one process could change under
each other.  So each fold computes exactly as in the serial run and the records must be identical, not
merely close.
"""

from __future__ import annotations

import json
import math

import pytest

from interprim.cli import main


def _evaluate(out, *extra):
    code = main(["evaluate", "--data", "synthetic", "--methods", "ip-position,prior,nn", "--quick",
                 "--no-figures", "--no-recognition", "--n-basis", "8", "--out", str(out), *extra])
    assert code == 0
    return json.loads((out / "results.json").read_text())


def _key(rec):
    return rec["dataset"], rec["task"], rec["method"], rec["demo"], rec["fraction"]


def _assert_close(x, y, where, rtol=1e-6):
    if isinstance(x, dict):
        assert isinstance(y, dict) and sorted(x) == sorted(y), where
        for k in x:
            _assert_close(x[k], y[k], (where, k), rtol)
    elif isinstance(x, (list, tuple)):
        assert isinstance(y, (list, tuple)) and len(x) == len(y), where
        for i, (u, v) in enumerate(zip(x, y)):
            _assert_close(u, v, (where, i), rtol)
    elif isinstance(x, float) and isinstance(y, float):
        assert (math.isnan(x) and math.isnan(y)) or abs(x - y) <= rtol * max(abs(x), abs(y), 1e-300), (where, x, y)
    else:
        assert x == y, (where, x, y)


@pytest.mark.slow
def test_evaluate_on_a_dask_cluster_equals_the_serial_run(tmp_path):
    import dask
    from dask.distributed import Client, LocalCluster, get_task_stream

    serial = _evaluate(tmp_path / "serial", "--jobs", "1")

    # generous timeouts: starting worker processes on a loaded 2-core machine can take long
    with dask.config.set({"distributed.comm.timeouts.connect": "300s", "distributed.comm.timeouts.tcp": "300s"}), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://",
                         dashboard_address=None) as cluster, Client(cluster) as client:
        client.wait_for_workers(2, timeout=600)
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        with get_task_stream(client=client) as stream:
            on_cluster = _evaluate(tmp_path / "dask", "--backend", "dask", "--scheduler", address, "--jobs", "2")
        tasks = stream.data
        workers = set(cluster.scheduler_info["workers"])

    # the work ran on the cluster's workers: one task per (held-out demo, method) fold at least
    n_folds = len({(r["demo"], r["method"].split("-dtw")[0].split("-oracle")[0]) for r in serial["folds"]})
    assert n_folds == 4 * 3  # --quick: 4 held-out demonstrations x 3 methods
    assert len(tasks) >= n_folds
    assert {t["worker"] for t in tasks} <= workers

    # same records: keys, strings and NaNs exactly, numbers to 1e-6 relative.  Not to the bit: the same fold
    # computed in another process can differ by a rounding (array alignment changes numpy's SIMD summation
    # order), and the likelihood phase, the vertex of a parabola through scores 0.2 % apart
    # (phase.likelihood.finish), moves by d_lp / (2 k h): for a flat posterior (curvature k ~ 10-100) and
    # rounding d_lp ~ 1e-13 |lp|, ~1e-10-1e-9 of the movement, which the errors carry ~10x.  Measured: up to 6e-9
    # (a fresh clone under stress-ng); any real difference between backends is orders of magnitude larger.
    assert len(on_cluster["folds"]) == len(serial["folds"]) > 0
    a = sorted(on_cluster["folds"], key=_key)
    b = sorted(serial["folds"], key=_key)
    for ra, rb in zip(a, b):
        _assert_close(ra, rb, _key(rb))
    assert on_cluster["config"] == serial["config"]
    # and they are real numbers: the IP's errors are finite and differ from the prior mean's
    ip = [r["rmse_ctrl"] for r in serial["folds"] if r["method"] == "ip-position"]
    prior = [r["rmse_ctrl"] for r in serial["folds"] if r["method"] == "prior"]
    assert all(math.isfinite(x) for x in ip + prior) and ip != prior
