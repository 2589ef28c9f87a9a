"""Builds the fuzz targets (libFuzzer, clang, -fsanitize=fuzzer,address,undefined), writes their seed
corpus and fuzzes each for a given time on one core, as many at once as --jobs (the machine's cores).

    .venv/bin/python tests/fuzz/run.py --seconds 600                 # every target, 10 minutes each
    .venv/bin/python tests/fuzz/run.py --seconds 60 exr rgbe         # some targets
    build/fuzz/fuzz_exr build/fuzz/crashes/exr/crash-...             # replay one input

Targets: exr (wenv_envmap_load on OpenEXR files), rgbe (wenv_read_rgbe), merl (wenv_read_merl, then
the table made into a material), matrix_cache (wenv_rotation_load).  Per target it reports the
inputs tried, the crashes (sanitizer reports, failed checks, leaks, inputs slower than --timeout,
allocations past --rss-limit-mb) with the reproducer's path, the slowest input and the corpus size,
and exits non-zero if any target crashed.  Objects, binaries, seeds and crash reproducers live in
build/fuzz/ (rebuilt when a source changes); each run starts from the seeds in a fresh corpus
folder unless --corpus-dir keeps one.
"""
import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CSRC = os.path.join(ROOT, "csrc")
TARGETS = ["exr", "rgbe", "merl", "matrix_cache"]

# The shipped code, with one limit lowered: images of at most 2^20 pixels (12 MB of floats) instead of
# 2^30, since a valid file of a few kilobytes may hold a gigabyte-sized image (scene/image_readers.h),
# and inputs that stay small keep the targets fast
CFLAGS = ["-std=c11", "-D_DEFAULT_SOURCE", "-O1", "-g", "-fno-omit-frame-pointer", "-fopenmp", "-Wall", "-Wextra",
          "-Werror", "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
          "-DWENV_IMAGE_MAX_PIXELS=((size_t)1<<20)",
          # at -O1 clang does not vectorise the loops marked `omp simd` and says so; speed is gcc's concern
          "-Wno-pass-failed"]
LIBS = ["-lOpenEXRCore", "-lcubature", "-lembree3", "-lz", "-lm"]


def pkg_config(*args):
    try:
        out = subprocess.run(["pkg-config", *args], check=True, capture_output=True, text=True,
                             env=child_env()).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return out.split()


def child_env():
    """The environment for the compiler and the targets, without what scripts/sanitize_tests.sh sets
    for python: the targets carry clang's sanitizer runtime, which cannot share a process with gcc's
    preloaded one."""
    env = dict(os.environ)
    for name in ("LD_PRELOAD", "ASAN_OPTIONS", "UBSAN_OPTIONS", "LSAN_OPTIONS"):
        env.pop(name, None)
    return env


def compile_if_stale(cmd, src_paths, out_path):
    newest = max(os.path.getmtime(p) for p in src_paths)
    if os.path.exists(out_path) and os.path.getmtime(out_path) >= newest:
        return
    build = subprocess.run(cmd, capture_output=True, text=True, env=child_env())
    if build.returncode != 0:
        raise SystemExit("fuzz build failed:\n" + " ".join(cmd) + "\n" + build.stderr[-6000:])


def build(build_dir, cc="clang", jobs=1):
    """Compiles csrc/ (without python/) with coverage for libFuzzer and the sanitizers, once per
    changed source, `jobs` compilers at once, and links one binary per target.  Returns {target: binary}."""
    obj_dir = os.path.join(build_dir, "obj")
    exr = [f for f in pkg_config("--cflags", "OpenEXR") if f.startswith("-I")] or ["-I/usr/include/OpenEXR"]
    flags = CFLAGS + ["-I" + CSRC] + exr
    # other flags than the last build's (this file changed): build everything again
    stamp = os.path.join(build_dir, "flags")
    used = " ".join([cc, *flags, *LIBS])
    if not os.path.exists(stamp) or open(stamp).read() != used:
        shutil.rmtree(obj_dir, ignore_errors=True)
        for old in [os.path.join(build_dir, "libwenv_core.a")] + [os.path.join(build_dir, f"fuzz_{t}") for t in TARGETS]:
            if os.path.exists(old):
                os.remove(old)
    os.makedirs(obj_dir, exist_ok=True)
    with open(stamp, "w") as f:
        f.write(used)
    headers = glob.glob(os.path.join(CSRC, "**", "*.h"), recursive=True)
    objects, compiles = [], []
    for src in sorted(glob.glob(os.path.join(CSRC, "**", "*.c"), recursive=True)):
        rel = os.path.relpath(src, CSRC)
        if rel.startswith("python" + os.sep):
            continue
        obj = os.path.join(obj_dir, rel.replace(os.sep, "__")[:-2] + ".o")
        compiles.append(([cc, *flags, "-fsanitize=fuzzer-no-link", "-c", src, "-o", obj], [src, *headers], obj))
        objects.append(obj)
    with ThreadPoolExecutor(jobs) as pool:
        list(pool.map(lambda job: compile_if_stale(*job), compiles))  # the first failure is raised here
    lib = os.path.join(build_dir, "libwenv_core.a")
    if not os.path.exists(lib) or os.path.getmtime(lib) < max(os.path.getmtime(o) for o in objects):
        if os.path.exists(lib):
            os.remove(lib)
        subprocess.run(["ar", "rcs", lib, *objects], check=True, env=child_env())
    binaries = {}
    for target in TARGETS:
        src = os.path.join(HERE, f"fuzz_{target}.c")
        exe = os.path.join(build_dir, f"fuzz_{target}")
        compile_if_stale([cc, *flags, "-fsanitize=fuzzer", src, lib, "-o", exe, *LIBS],
                         [src, lib, os.path.join(HERE, "fuzz_input.h")], exe)
        binaries[target] = exe
    return binaries


def sanitizer_env():
    env = child_env()
    env["OMP_NUM_THREADS"] = "1"  # one core: the parallel loops run on one thread
    # leaks are checked by libFuzzer after every input that allocated more than it freed
    env["ASAN_OPTIONS"] = "detect_leaks=1:abort_on_error=0:symbolize=1:allocator_may_return_null=0"
    env["UBSAN_OPTIONS"] = "print_stacktrace=1:halt_on_error=1"
    return env


def stat(text, name, cast=int):
    m = re.findall(r"^stat::%s:\s*(\S+)" % name, text, re.M)
    return cast(m[-1]) if m else None


def input_times(exe, paths, env, timeout, rss_limit_mb):
    """Milliseconds each input takes, replayed one by one (libFuzzer's 'Executed ... in N ms'), and
    the replay's failure if one failed (which the run itself would have reported)."""
    times, failure = {}, None
    for i in range(0, len(paths), 200):
        run = subprocess.run([exe, f"-timeout={timeout}", f"-rss_limit_mb={rss_limit_mb}", *paths[i:i + 200]],
                             capture_output=True, text=True, env=env)
        for path, ms in re.findall(r"^Executed (.+) in (\d+) ms$", run.stderr, re.M):
            times[path] = int(ms)
        if run.returncode != 0 and failure is None:
            failure = "replaying the corpus failed (exit status %d): %s" % (run.returncode, run.stderr[-2000:])
    return times, failure


def fuzz(target, exe, seconds, seed_dir, corpus_dir, crash_dir, timeout, rss_limit_mb, log_path):
    os.makedirs(corpus_dir, exist_ok=True)
    os.makedirs(crash_dir, exist_ok=True)
    env = sanitizer_env()
    cmd = [exe, f"-max_total_time={seconds}", f"-timeout={timeout}", f"-rss_limit_mb={rss_limit_mb}",
           "-report_slow_units=1", "-print_final_stats=1", "-max_len=65536", f"-artifact_prefix={crash_dir}/"]
    dictionary = os.path.join(HERE, f"{target}.dict")
    if os.path.exists(dictionary):
        cmd.append(f"-dict={dictionary}")
    cmd += [corpus_dir, seed_dir]
    t0 = time.monotonic()
    with open(log_path, "w") as log:
        rc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env).returncode
    elapsed = time.monotonic() - t0
    text = open(log_path, errors="replace").read()
    written = re.findall(r"Test unit written to (\S+)", text)
    slow_units = [c for c in written if os.path.basename(c).startswith("slow-unit-")]
    crashes = [c for c in written if c not in slow_units]
    if rc != 0 and not crashes:
        crashes = ["(no reproducer written: exit status %d, see %s)" % (rc, log_path)]
    corpus = sorted(glob.glob(os.path.join(corpus_dir, "*"))) + sorted(glob.glob(os.path.join(seed_dir, "*")))
    times, failure = input_times(exe, corpus, env, timeout, rss_limit_mb)
    if failure:
        crashes.append(failure)
    slowest = max(times.items(), key=lambda kv: kv[1]) if times else (None, 0)
    corp = re.findall(r"corp: (\d+)/", text)
    return {
        "target": target,
        "execs": stat(text, "number_of_executed_units") or 0,
        "seconds": round(elapsed, 1),
        "crashes": crashes,
        "slow_units": slow_units,
        "slowest_unit_s": stat(text, "slowest_unit_time_sec") or 0,
        "slowest_corpus_ms": slowest[1],
        "slowest_corpus_input": slowest[0],
        "corpus": int(corp[-1]) if corp else len(corpus),
        "peak_rss_mb": stat(text, "peak_rss_mb") or 0,
        "log": log_path,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("targets", nargs="*", metavar="target", help="some of %s (default: all)" % ", ".join(TARGETS))
    ap.add_argument("--seconds", type=int, default=30, help="fuzzing time per target (default 30)")
    ap.add_argument("--timeout", type=int, default=10, help="seconds after which one input is a crash (10)")
    ap.add_argument("--rss-limit-mb", type=int, default=2048, help="memory past which an input is a crash (2048)")
    ap.add_argument("--build-dir", default=os.path.join(ROOT, "build", "fuzz"))
    ap.add_argument("--corpus-dir", help="keep each target's corpus in CORPUS_DIR/<target> (default: a fresh one)")
    ap.add_argument("--json", help="also write the results to this file")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="targets fuzzed (and sources compiled) at once, each on one core (default: the cores)")
    args = ap.parse_args(argv)
    targets = args.targets or TARGETS
    if set(targets) - set(TARGETS):
        ap.error("unknown target(s): %s" % ", ".join(sorted(set(targets) - set(TARGETS))))
    if not shutil.which("clang"):
        raise SystemExit("clang is missing: run scripts/setup.sh")
    t0 = time.monotonic()
    if args.jobs < 1:
        ap.error("--jobs must be 1 or more")
    binaries = build(args.build_dir, jobs=args.jobs)
    seed_root = os.path.join(args.build_dir, "seeds")
    sys.path.insert(0, HERE)
    from seeds import write_seeds

    write_seeds(seed_root, targets)
    print("built and seeded in %.0f s" % (time.monotonic() - t0), flush=True)
    results = []
    with tempfile.TemporaryDirectory() as scratch, ThreadPoolExecutor(args.jobs) as pool:
        runs = [pool.submit(fuzz, target, binaries[target], args.seconds, os.path.join(seed_root, target),
                            os.path.join(args.corpus_dir or scratch, target),
                            os.path.join(args.build_dir, "crashes", target), args.timeout, args.rss_limit_mb,
                            os.path.join(args.build_dir, f"{target}.log"))
                for target in targets]
        for target, run in zip(targets, runs):  # reported in the targets' order as each ends
            r = run.result()
            results.append(r)
            print("%-13s %10d inputs in %5.0f s, %d crash(es), slowest corpus input %d ms, corpus %d, peak %d MB"
                  % (target, r["execs"], r["seconds"], len(r["crashes"]), r["slowest_corpus_ms"], r["corpus"],
                     r["peak_rss_mb"]), flush=True)
            for c in r["crashes"]:
                print("    crash: " + c)
            for c in r["slow_units"]:
                print("    slow input (over 1 s): " + c)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 1 if any(r["crashes"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
