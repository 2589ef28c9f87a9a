"""Sweeps (wenv_sweep.py) on a local process pool and on Dask distributed (a LocalCluster of two
worker processes): every result written as it comes, a run resumed from its results file, a failed
job retried once and then reported with its inputs while the rest go on, a killed worker losing
nothing, Blender work in the workers, and bad jobs named."""
import json
import os

import pytest

import wenv_sweep as sweep
from tests.helpers import sweep_jobs


def lines(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f]


def test_a_local_sweep_writes_every_result_as_it_comes(tmp_path):
    out = tmp_path / "sweep.jsonl"
    seen = []
    report = sweep.run([{"x": x} for x in range(12)], sweep_jobs.square, results=str(out), workers=2,
                       progress=lambda done, total, failed, job, error: seen.append((done, total, failed)))
    assert report.results == {sweep.key({"x": x}): x * x for x in range(12)}
    assert (report.ran, report.resumed, report.failed) == (12, 0, [])
    assert sorted(done for done, _, _ in seen) == list(range(1, 13)) and {t for _, t, _ in seen} == {12}
    assert sorted((row["job"]["x"], row["result"]) for row in lines(out)) == [(x, x * x) for x in range(12)]


def test_an_interrupted_sweep_resumes_where_it_stopped(tmp_path):
    """A results file holding 4 of 10 jobs (and a torn last line, as a killed write leaves): the run
    does only the other 6, and reports all 10."""
    out = tmp_path / "sweep.jsonl"
    calls = tmp_path / "calls"
    calls.mkdir()
    with open(out, "w") as f:
        for x in range(4):
            f.write(json.dumps({"job": {"x": x, "folder": str(calls)}, "result": x * 10}) + "\n")
        f.write('{"job": {"x": 4, "fol')
    jobs = [{"x": x, "folder": str(calls)} for x in range(10)]
    report = sweep.run(jobs, sweep_jobs.counted, results=str(out), workers=2, progress=None)
    assert (report.ran, report.resumed) == (6, 4)
    assert sorted(int(name.split("-")[0]) for name in os.listdir(calls)) == list(range(4, 10))
    assert report.results == {sweep.key(job): job["x"] * 10 for job in jobs}
    again = sweep.run(jobs, sweep_jobs.counted, results=str(out), workers=2, progress=None)
    assert (again.ran, again.resumed) == (0, 10) and len(os.listdir(calls)) == 6


def test_a_failed_job_is_retried_once_then_reported_with_its_inputs(tmp_path):
    out = tmp_path / "sweep.jsonl"
    flaky = {"x": 1, "marker": str(tmp_path / "flaky")}
    report = sweep.run([flaky], sweep_jobs.first_attempt_fails, results=str(out), workers=1, progress=None)
    assert report.results == {sweep.key(flaky): 2} and report.retried == 1 and report.failed == []
    report = sweep.run([{"x": 7}, {"x": 8}], sweep_jobs.always_fails, results=str(out), workers=2, progress=None)
    assert sorted(job["x"] for job, _ in report.failed) == [7, 8] and report.retried == 2
    assert all("ValueError: no result for" in error for _, error in report.failed)
    assert sorted(row["job"]["x"] for row in lines(out) if "error" in row) == [7, 8]


def test_a_killed_local_worker_loses_nothing(tmp_path):
    jobs = [{"x": x, "marker": str(tmp_path / "died")} for x in range(8)]
    report = sweep.run(jobs, sweep_jobs.dies_once, results=str(tmp_path / "sweep.jsonl"), workers=2,
                       progress=None)
    assert os.path.exists(tmp_path / "died") and report.failed == []
    assert report.results == {sweep.key(job): -job["x"] for job in jobs}


def test_blender_work_on_this_machine_runs_in_blender_processes_of_its_own(tmp_path):
    """Threads of this process (which has Blender loaded) each drive a Blender process of their own:
    the readings are those of the add-on, one Blender per thread."""
    import concurrent.futures
    jobs = [{"roughness": r} for r in (0.05, 0.5)]
    with concurrent.futures.ThreadPoolExecutor(2) as threads:
        report = sweep.run(jobs, sweep.in_blender(sweep_jobs.blender_gloss), executor=threads, progress=None)
    assert report.failed == [] and report.results[sweep.key(jobs[0])] > report.results[sweep.key(jobs[1])] > 0


def test_bad_jobs_are_named():
    with pytest.raises(TypeError, match=r"jobs\[1\] must be a dict"):
        sweep.run([{"x": 1}, 2], sweep_jobs.square)
    with pytest.raises(TypeError, match=r"jobs\[0\] must hold JSON values"):
        sweep.run([{"x": object()}], sweep_jobs.square)


@pytest.fixture(scope="module")
def dask_client():
    import dask
    from dask.distributed import Client, LocalCluster
    dask.config.set({"distributed.worker.daemon": False})  # in_blender's Blender process is a worker's child
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_a_dask_sweep_runs_blender_work_in_the_workers(dask_client, tmp_path):
    """Gloss readings of Principled paints made in each worker's own Blender, on a two-worker
    LocalCluster: every reading is the one this process's add-on gives, and falls with roughness."""
    from addon import compat, gloss, materials
    jobs = [{"roughness": r} for r in (0.05, 0.2, 0.5)]
    report = sweep.run(jobs, sweep.in_blender(sweep_jobs.blender_gloss), executor=dask_client.get_executor(),
                       results=str(tmp_path / "gloss.jsonl"), progress=None)
    assert report.failed == [] and report.ran == 3
    readings = [report.results[sweep.key(job)] for job in jobs]
    assert readings[0] > readings[1] > readings[2] > 0
    import addon
    addon.register()
    try:
        mat = compat.new_node_material("here")
        mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.2
        here = gloss.gloss_readings(materials.material_key(mat.wenv))[60]
    finally:
        addon.unregister()
    assert readings[1] == pytest.approx(here, rel=1e-6)


def test_a_killed_dask_worker_loses_nothing_and_failures_are_reported(dask_client, tmp_path):
    jobs = [{"x": x, "marker": str(tmp_path / "died")} for x in range(6)]
    report = sweep.run(jobs, sweep_jobs.dies_once, executor=dask_client.get_executor(),
                       results=str(tmp_path / "sweep.jsonl"), progress=None)
    assert os.path.exists(tmp_path / "died") and report.failed == []
    assert report.results == {sweep.key(job): -job["x"] for job in jobs}
    report = sweep.run([{"x": 3}], sweep_jobs.always_fails, executor=dask_client.get_executor(), progress=None)
    assert [job for job, _ in report.failed] == [{"x": 3}] and report.retried == 1
