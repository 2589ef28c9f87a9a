"""What the Python fuzzers (api.py, addon.py) share: an iteration's own generator, the choices drawn
from it, and counts of what happened."""
import argparse
import collections
import json
import sys


class Draws:
    def __init__(self, rng, tmp, slow, verbose=False):
        self.r = rng
        self.tmp = tmp  # a folder for the files an iteration writes
        self.slow = slow
        self.verbose = verbose
        self.counts = collections.Counter()

    def pick(self, seq):
        return seq[self.r.integers(len(seq))]

    def chance(self, p):
        return self.r.random() < p


def arguments(doc, iterations, slow, slow_help):
    """The command line both fuzzers take."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--iterations", type=int, default=iterations)
    ap.add_argument("--only", type=int, help="replay this iteration alone, printing every step")
    ap.add_argument("--slow", type=float, default=slow, help=slow_help)
    ap.add_argument("--json", help="write the summary and any finding here")
    return ap.parse_args()


def report(args, summary, finding):
    """Prints the summary (and writes it to --json) with any finding; exit status 1 on a finding."""
    summary["finding"] = finding
    wenv = sys.modules.get("wenv")
    summary["wenv"] = wenv.__file__ if wenv is not None else None  # which build was fuzzed
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)
    counts = summary["counts"]
    calls = f", {counts['calls']} calls" if "calls" in counts else ""
    print(f"{summary['iterations']} iterations in {summary['seconds']:.1f} s{calls}")
    for key in sorted(counts):
        if key != "calls":
            print(f"  {key}: {counts[key]}")
    if finding:
        print(f"FOUND at iteration {finding['iteration']} (replay: --seed {args.seed} --only {finding['iteration']}): "
              f"{finding['what']}\n{finding.get('traceback', '')}")
        sys.exit(1)
