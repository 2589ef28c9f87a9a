"""wenv_sweep: many jobs of one function (gloss readings of a catalogue, shades over a material x HDRI x
roughness grid) on any concurrent.futures.Executor -- a local process pool by default, or a Dask
cluster's (Client.get_executor()) -- with progress as jobs finish, one retry of a failed job, and
every result written as it comes, so an interrupted sweep resumes where it stopped.

    import wenv_sweep
    report = wenv_sweep.run(jobs, fn, results="out/sweep.jsonl")            # this machine
    from dask.distributed import Client
    report = wenv_sweep.run(jobs, wenv_sweep.in_blender(fn), results="out/sweep.jsonl",
                            executor=Client("tcp://scheduler:8786").get_executor())

A job is a dict of JSON values, passed to fn as keywords in a worker; fn must be importable there
(a module's function, or a script's under Dask, which ships it by value) and return JSON values.
A module of its own beside `wenv` (shipped with it, in the add-on's wheel too), importing neither
bpy nor wenv: a Dask worker unpickles jobs without starting Blender.  Blender runs Python in one
main thread, and Dask runs tasks in worker threads: in_blender(fn) runs fn in a Blender process of
each Dask worker's own (docs/python.md, "Sweeps")."""
import atexit
import concurrent.futures
import json
import multiprocessing
import os
import pickle
import sys
import threading
from concurrent.futures.process import BrokenProcessPool

# A job whose worker died this many times is reported rather than run again (it may be what kills it)
MAX_DEATHS = 3


class Report:
    """What a sweep gave: results {key: result} (every job's, those of earlier runs included),
    failed [(job, error text)] after its retry, and the counts of this run."""

    def __init__(self):
        self.results, self.failed = {}, []
        self.ran = self.resumed = self.retried = 0

    def __repr__(self):
        return (f"sweep.Report({len(self.results)} results, {len(self.failed)} failed; {self.ran} run now, "
                f"{self.resumed} from before, {self.retried} retried)")


def key(job):
    """A job's identity in the results file: its inputs as canonical JSON."""
    return json.dumps(job, sort_keys=True, separators=(",", ":"))


def read_results(path):
    """{key: result} of the jobs a results file holds a result for (a torn last line, from an
    interrupted write, is ignored)."""
    done = {}
    if path and os.path.exists(path):
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    row = json.loads(line)
                except ValueError:
                    continue
                if "result" in row:
                    done[key(row["job"])] = row["result"]
    return done


def print_progress(done, total, failed, job, error):
    """The default progress: one line per finished job."""
    state = f"failed: {error}" if error else "done"
    print(f"sweep: {done}/{total} ({failed} failed) {key(job)} {state}", flush=True)


def _check_jobs(jobs):
    for i, job in enumerate(jobs):
        if not isinstance(job, dict):
            raise TypeError(f"jobs[{i}] must be a dict of keyword arguments, not {type(job).__name__}")
        try:
            key(job)
        except TypeError as exc:
            raise TypeError(f"jobs[{i}] must hold JSON values (numbers, strings, lists, dicts): {exc}") from None


def run(jobs, fn, *, executor=None, results=None, retries=1, progress=print_progress, workers=None):
    """Runs fn(**job) for each job, on `executor` (default: a process pool of `workers` processes on
    this machine, made and shut down here, and made again if a worker dies; Blender work goes through
    in_blender, for a process that loaded Blender forks workers that hang in it), and returns a
    Report.

    results: a JSON-lines file each finished job is appended to as it finishes ({"job", "result"}
    or {"job", "error"}); jobs it already holds a result for are not run again.  A job that raises
    is run again `retries` times, then reported with its inputs while the rest go on.  A worker
    killed mid-job loses nothing: the local pool is made again and its jobs run again; Dask runs a
    lost worker's jobs elsewhere itself.  progress(done, total, failed, job, error) as each job
    finishes (None: silent)."""
    jobs = list(jobs)
    _check_jobs(jobs)
    report = Report()
    report.results = read_results(results)
    todo, seen = [], set()
    for job in jobs:
        k = key(job)
        if k in report.results:
            report.resumed += 1
        elif k not in seen:
            seen.add(k)
            todo.append(job)
    if results:
        os.makedirs(os.path.dirname(os.path.abspath(results)), exist_ok=True)
    own = executor is None
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=workers) if own else executor
    out = open(results, "a", encoding="utf-8") if results else None
    if out is not None and out.tell() > 0 and not _ends_a_line(results):
        out.write("\n")  # after a line torn by an interrupted write, which stays unread
    attempts = {key(job): 0 for job in todo}
    deaths = dict.fromkeys(attempts, 0)
    done_count = report.resumed

    def finish(job, value=None, error=None):
        """A job's result or failure, recorded, written and told."""
        nonlocal done_count
        if error is None:
            report.results[key(job)] = value
            report.ran += 1
            _write(out, {"job": job, "result": value})
        else:
            report.failed.append((job, error))
            _write(out, {"job": job, "error": error})
        done_count += 1
        if progress:
            progress(done_count, len(jobs), len(report.failed), job, error)

    # a pool made here gets fn by value (cloudpickle), so a script's or a notebook's own function will
    # do; an executor passed in ships it its own way (Dask by value too)
    submit = _by_value(fn) if own else (lambda job, into: into.submit(fn, **job))
    try:
        pending = {submit(job, pool): job for job in todo}
        while pending:
            finished, _ = concurrent.futures.wait(pending, return_when=concurrent.futures.FIRST_COMPLETED)
            broken = []
            for future in finished:
                job = pending.pop(future)
                k = key(job)
                try:
                    value = future.result()
                except BrokenProcessPool:
                    deaths[k] += 1  # its worker died: not surely the job's fault, so run it again
                    if deaths[k] < MAX_DEATHS:
                        broken.append(job)
                    else:
                        finish(job, error=f"its worker died {MAX_DEATHS} times")
                    continue
                except Exception as exc:  # noqa: BLE001 -- a job's failure is reported, not raised
                    attempts[k] += 1
                    if attempts[k] <= retries:
                        report.retried += 1
                        pending[submit(job, pool)] = job
                    else:
                        finish(job, error=f"{type(exc).__name__}: {exc}")
                    continue
                finish(job, value=value)
            if broken:
                if not own:
                    raise RuntimeError("the executor's worker pool broke (a worker died): a pool passed in is "
                                       "not made again; run again to resume") from None
                broken += list(pending.values())
                pool.shutdown(wait=False, cancel_futures=True)
                pool = concurrent.futures.ProcessPoolExecutor(max_workers=workers)
                pending = {submit(job, pool): job for job in broken}
    finally:
        if out:
            out.close()
        if own:
            pool.shutdown(wait=True, cancel_futures=True)
    return report


def _by_value(fn):
    import cloudpickle
    blob = cloudpickle.dumps(fn)
    return lambda job, pool: pool.submit(_call_pickled, blob, job)


def _ends_a_line(path):
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) == b"\n"


def _write(out, row):
    if out is not None:
        out.write(json.dumps(row, sort_keys=True) + "\n")
        out.flush()
        os.fsync(out.fileno())


# Per process: the Blender process in_blender runs jobs in (made on first use)
_blender = {}


class in_blender:
    """fn wrapped to run in a process of its own whose main thread imports Blender, one per worker
    process and kept there (so a Dask worker, whose tasks run in threads, runs bpy work as Blender
    needs it).  fn travels by value (cloudpickle, as Dask ships functions), so a script's own
    function will do.  A Blender process that dies is made again for the next job (the sweep's
    retry)."""

    def __init__(self, fn):
        self.fn = fn
        self.__name__ = getattr(fn, "__name__", "job")

    def __call__(self, **job):
        import cloudpickle
        here = (os.getpid(), threading.get_ident())  # a Blender of its own per worker thread too
        runner = _blender.get(here)
        if runner is None:
            runner = concurrent.futures.ProcessPoolExecutor(max_workers=1,
                                                            mp_context=multiprocessing.get_context("spawn"))
            if not _blender:
                atexit.register(_close_blenders)
            _blender[here] = runner
        saved = sys.path[:]
        sys.path[:] = _without_blender_folders(sys.path)  # what the process it starts now inherits
        try:
            future = runner.submit(_call_pickled, cloudpickle.dumps(self.fn), job)
        finally:
            sys.path[:] = saved
        try:
            return future.result()
        except BrokenProcessPool as exc:
            _blender.pop(here, None)
            # its Blender died: the job failed (the sweep retries it), not this worker
            raise RuntimeError(f"the job's Blender process died ({exc})") from None


def _close_blenders():
    for runner in _blender.values():
        runner.shutdown(wait=False, cancel_futures=True)
    _blender.clear()


def _without_blender_folders(path):
    """sys.path without Blender's own module folders (a process that imported bpy has them): in a
    new process they would shadow the bpy package itself."""
    inner = os.sep + "bpy" + os.sep
    return [p for p in path if not (inner in p and os.sep + "scripts" in p)]


def _call_pickled(blob, job):
    sys.path[:] = _without_blender_folders(sys.path)
    return pickle.loads(blob)(**job)
