"""Sweeps on Dask against running the jobs one after another: 1,000 gloss readings (wenv.gloss of
Principled paints over a roughness x metallic x coat grid, in the workers' threads) and 200 shades
of Suzanne subdivided 3 times (31,658 vertices; 20 roughnesses x 10 World rotations at `default`,
each job in a Blender process of its worker's, as examples/addon_shade_sweep.py runs them) on a
LocalCluster of 2 worker processes, beside the same jobs run serially in this process (the gloss)
or in one Blender process (the shades).  Prints the times, the speed-up and the overhead per job
(the cluster's wall time x workers / jobs, less a job's own time in its worker), and writes JSON.

    python benchmarks/bench_sweep.py [--gloss 1000] [--shades 200] [--out out/bench_sweep.json]
"""
import argparse
import concurrent.futures
import json
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "examples")]
import wenv_sweep  # noqa: E402


def gloss_job(roughness, metallic, coat):
    import wenv
    t = time.perf_counter()
    g = wenv.gloss(wenv.Principled(base_color=(0.5, 0.1, 0.05), roughness=roughness, metallic=metallic,
                                   coat_weight=coat), (20, 60, 85))
    return {"gu": [float(x) for x in g], "seconds": time.perf_counter() - t}


def shade_job(roughness, rotation, settings):
    import addon_shade_sweep
    t = time.perf_counter()
    row = addon_shade_sweep.shade_one(roughness, rotation, settings)
    return {"mean_r": row["mean_r"], "seconds": time.perf_counter() - t}


def timed_sweep(jobs, fn, executor):
    t = time.perf_counter()
    report = wenv_sweep.run(jobs, fn, executor=executor, progress=None)
    wall = time.perf_counter() - t
    assert not report.failed, report.failed[:3]
    seconds = [report.results[wenv_sweep.key(j)]["seconds"] for j in jobs]
    return wall, sum(seconds) / len(seconds), report


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gloss", type=int, default=1000)
    ap.add_argument("--shades", type=int, default=200)
    ap.add_argument("--out", default=os.path.join("out", "bench_sweep.json"))
    args = ap.parse_args()
    import dask
    from dask.distributed import Client, LocalCluster
    dask.config.set({"distributed.worker.daemon": False})  # in_blender's Blender is a worker's child

    side = round(args.gloss ** (1 / 3))
    gloss_jobs = [{"roughness": 0.02 + 0.9 * i / side, "metallic": j / max(side - 1, 1), "coat": k / max(side - 1, 1)}
                  for i in range(side) for j in range(side) for k in range(side)][:args.gloss]
    gloss_jobs += [{"roughness": 0.5, "metallic": 0.0, "coat": 0.5 + 1e-3 * n}
                   for n in range(args.gloss - len(gloss_jobs))]
    settings = {"blend": None, "object": "Suzanne", "quality": "default", "max_luminance": 4.0, "images": False,
                "size": 64, "out": tempfile.mkdtemp(prefix="wenv-sweep-"), "levels": 3}
    rotations = 10
    shade_jobs = [{"roughness": 0.02 + 0.9 * i / (args.shades // rotations), "rotation": 36.0 * k, "settings": settings}
                  for i in range(args.shades // rotations) for k in range(rotations)]
    rows = {}
    with concurrent.futures.ThreadPoolExecutor(1) as one:
        rows["gloss serial"] = timed_sweep(gloss_jobs, gloss_job, one)[:2]
        rows["shade serial"] = timed_sweep(shade_jobs, wenv_sweep.in_blender(shade_job), one)[:2]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        executor = client.get_executor()
        rows["gloss on 2 Dask workers"] = timed_sweep(gloss_jobs, gloss_job, executor)[:2]
        rows["shade on 2 Dask workers"] = timed_sweep(shade_jobs, wenv_sweep.in_blender(shade_job), executor)[:2]
    out = []
    print(f"{'sweep':26s} {'jobs':>5s} {'wall s':>8s} {'job ms':>8s} {'speed-up':>9s} {'overhead ms/job':>16s}")
    for kind, jobs in (("gloss", gloss_jobs), ("shade", shade_jobs)):
        serial_wall, _ = rows[f"{kind} serial"]
        wall, job_s = rows[f"{kind} on 2 Dask workers"]
        overhead = wall * 2 / len(jobs) - job_s
        for name in (f"{kind} serial", f"{kind} on 2 Dask workers"):
            w, s = rows[name]
            speed = serial_wall / w
            print(f"{name:26s} {len(jobs):5d} {w:8.1f} {1e3 * s:8.1f} {speed:9.2f} "
                  f"{(1e3 * overhead if 'Dask' in name else float('nan')):16.1f}")
            out.append({"sweep": name, "jobs": len(jobs), "wall_s": w, "job_ms": 1e3 * s, "speedup": speed,
                        "overhead_ms_per_job": 1e3 * overhead if "Dask" in name else None})
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"command": "python benchmarks/bench_sweep.py " + " ".join(sys.argv[1:]), "rows": out}, f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
