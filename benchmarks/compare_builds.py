"""Runs benchmarks against two builds of the `wenv` module side by side, alternating them round by
round so that the machine's load falls on both alike, and prints every figure's median per build
and their ratio.  For checking that a change of structure left speed and accuracy where they were.

    .venv/bin/python benchmarks/compare_builds.py BEFORE_DIR AFTER_DIR [--rounds 3]
        [--benchmarks bench_shade,bench_peers,bench_gloss,accuracy,speed_breakdown]

Each DIR holds a built `wenv` extension (for example `python setup.py build_ext --build-lib DIR`
run in a checkout of the other commit).  Every benchmark writes its JSON to out/; each run's is
kept as out/compare_builds/<benchmark>.<build>.<round>.json, and the summary goes to
out/compare_builds.json."""
import argparse
import json
import os
import statistics
import subprocess
import sys

from measure import OUT, ROOT

OUTPUTS = {  # what each benchmark writes, relative to out/
    "bench_shade": "bench_shade.json",
    "bench_peers": "bench_peers.json",
    "bench_gloss": "bench_gloss.json",
    "accuracy": "accuracy.json",
    "speed_breakdown": "speed_breakdown.json",
    "bench_scattered": "bench_scattered.json",
}


def numbers(tree, prefix=""):
    """Flattens a JSON tree into {"a.b.0.c": value} for its numeric leaves."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from numbers(v, f"{prefix}{k}.")
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from numbers(v, f"{prefix}{i}.")
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool):
        yield prefix[:-1], float(tree)


def run(benchmark, build, folder, round_, keep):
    env = dict(os.environ, PYTHONPATH=os.path.abspath(folder))
    script = os.path.join(ROOT, "benchmarks", benchmark + ".py")
    check = "import wenv, os, sys; sys.stdout.write(os.path.dirname(os.path.abspath(wenv.__file__)))"
    # run from out/: "python -c" puts the current folder first on sys.path, and the checkout holds a build
    loaded = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, check=True,
                            cwd=OUT).stdout
    if os.path.realpath(loaded) != os.path.realpath(folder):
        sys.exit(f"compare_builds: {build} imports wenv from {loaded}, not {folder}")
    subprocess.run([sys.executable, script], env=env, check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    with open(os.path.join(OUT, OUTPUTS[benchmark])) as fp:
        data = json.load(fp)
    with open(os.path.join(keep, f"{benchmark}.{build}.{round_}.json"), "w") as fp:
        json.dump(data, fp)
    return dict(numbers(data))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--benchmarks", default=",".join(OUTPUTS))
    args = ap.parse_args()
    benchmarks = args.benchmarks.split(",")
    unknown = [b for b in benchmarks if b not in OUTPUTS]
    if unknown:
        ap.error(f"unknown benchmarks {unknown}; known: {', '.join(OUTPUTS)}")
    keep = os.path.join(OUT, "compare_builds")
    os.makedirs(keep, exist_ok=True)  # makes out/ too
    runs = {b: {"before": [], "after": []} for b in benchmarks}
    for r in range(args.rounds):
        for b in benchmarks:
            order = ("before", "after") if r % 2 == 0 else ("after", "before")
            for build in order:
                print(f"round {r + 1}/{args.rounds}: {b} with {build}", flush=True)
                runs[b][build].append(run(b, build, getattr(args, build), r, keep))
    summary = {}
    for b in benchmarks:
        keys = sorted(set.intersection(*(set(d) for d in runs[b]["before"] + runs[b]["after"])))
        rows = {}
        for k in keys:
            before = statistics.median(d[k] for d in runs[b]["before"])
            after = statistics.median(d[k] for d in runs[b]["after"])
            ratio = after / before if before else (1.0 if after == before else float("inf"))
            rows[k] = {"before": before, "after": after, "ratio": ratio}
        summary[b] = rows
        print(f"\n{b}: median of {args.rounds} runs per build (after / before)")
        for k, row in rows.items():
            print(f"  {k:60s} {row['before']:12.6g} {row['after']:12.6g}  {row['ratio']:.3f}")
    with open(os.path.join(OUT, "compare_builds.json"), "w") as fp:
        json.dump(dict(before=args.before, after=args.after, rounds=args.rounds, figures=summary), fp, indent=1)


if __name__ == "__main__":
    main()
