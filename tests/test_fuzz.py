"""A short fuzzing run of every file reader (tests/fuzz/run.py: libFuzzer with AddressSanitizer and
UndefinedBehaviorSanitizer, 15 s per target, two at a time on two cores, with the build): no crash, leak,
failed check or input slower than 10 s, and each target tried many inputs and found new ones
beyond its seeds.  The seeds include the inputs that once broke a reader, so they are replayed
first.  Then the Python API's random-input run (tests/fuzz/api.py) and the add-on's random scenes
and use (tests/fuzz/addon_scenes.py), a fixed seed's iterations each."""
import json
import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "fuzz"))
from run import TARGETS  # noqa: E402
import wenv  # noqa: E402

SECONDS = 15
MIN_INPUTS = 10_000  # each target runs 10^4 to 10^5 inputs a second here


@pytest.fixture(scope="module")
def fuzz_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("fuzz") / "results.json"
    run = subprocess.run([sys.executable, os.path.join(ROOT, "tests", "fuzz", "run.py"), "--seconds", str(SECONDS),
                          "--json", str(out)], capture_output=True, text=True, timeout=900)
    assert out.exists(), run.stdout + run.stderr[-4000:]
    results = {r["target"]: r for r in json.load(open(out))}
    return run, results


def log_tail(result):
    with open(result["log"], errors="replace") as f:
        return f.read()[-6000:]


@pytest.mark.parametrize("target", TARGETS)
def test_fuzz_target_finds_nothing(fuzz_results, target):
    run, results = fuzz_results
    r = results[target]
    assert r["crashes"] == [], log_tail(r)
    assert r["execs"] >= MIN_INPUTS, log_tail(r)
    seeds = os.listdir(os.path.join(ROOT, "build", "fuzz", "seeds", target))
    assert r["corpus"] > len(seeds), r  # the fuzzer got past what the seeds cover
    assert r["slowest_corpus_ms"] < 10_000, r


def test_fuzz_script_reports_and_exits_cleanly(fuzz_results):
    run, results = fuzz_results
    assert run.returncode == 0, run.stdout + run.stderr[-4000:]
    for target in TARGETS:  # one line per target: inputs, crashes, slowest input, corpus
        line = re.search(r"^%s +(\d+) inputs in .* 0 crash\(es\), slowest corpus input \d+ ms, corpus (\d+)" % target,
                         run.stdout, re.M)
        assert line and int(line.group(1)) == results[target]["execs"], run.stdout


API_ITERATIONS = 1500


def run_fuzz_script(tmp_path, script, *args):
    """tests/fuzz/<script> in a child process with the wenv this process imported first on its path
    (under scripts/sanitize_tests.sh, the sanitized build) and a cache folder of its own: its JSON
    summary, once the run found nothing."""
    out = tmp_path / (script + ".json")
    path = [os.path.dirname(wenv.__file__)] + ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])
    env = dict(os.environ, WENV_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=os.pathsep.join(path))
    run = subprocess.run([sys.executable, os.path.join(ROOT, "tests", "fuzz", script), *args, "--json", str(out)],
                         capture_output=True, text=True, timeout=900, env=env)
    assert out.exists(), f"exit {run.returncode}\n" + run.stdout[-3000:] + run.stderr[-6000:]
    summary = json.load(open(out))
    assert summary["wenv"] == wenv.__file__  # the build this run tests
    assert summary["finding"] is None and run.returncode == 0, run.stdout[-6000:]
    return summary


def test_api_survives_random_input(tmp_path):
    """Random odd and bad arguments to every public function and method: each raises TypeError,
    ValueError or OSError (or returns finite values for finite input) and nothing crashes or hangs;
    enough calls got through to shade, so the run reached the shading code and not only the checks."""
    summary = run_fuzz_script(tmp_path, "api.py", "--seed", "0", "--iterations", str(API_ITERATIONS))
    counts = summary["counts"]
    assert summary["iterations"] == API_ITERATIONS
    for error in ("TypeError", "ValueError", "OSError"):
        assert counts.get("raised " + error, 0) >= 50, counts
    assert counts.get("returned Shader", 0) >= 50, counts
    assert counts.get("returned Shader.shade", 0) + counts.get("returned Shader.shade_mesh", 0) >= 30, counts
    assert counts.get("returned Shader.set_environment", 0) + counts.get("returned Shader.set_material", 0) >= 20, counts
    assert counts.get("returned glossmeter gloss", 0) + counts.get("returned glossmeter measure", 0) >= 3, counts


ADDON_ITERATIONS = 200


def test_addon_survives_random_scenes_and_use(tmp_path):
    """Random scenes (odd Worlds, meshes, materials, settings, cameras) and random use of the add-on
    (its operators, the live session, gloss readings, the panels' drawing, frame changes, undo,
    save and reload): no operator fails with a traceback, no exception escapes a getter, update,
    handler or panel, every colour written is finite and non-negative, nothing crashes or hangs; and
    the run reached the shading, not only the set-up checks."""
    summary = run_fuzz_script(tmp_path, "addon_scenes.py", "--seed", "0", "--iterations", str(ADDON_ITERATIONS))
    counts = summary["counts"]
    assert summary["iterations"] == ADDON_ITERATIONS
    assert counts.get("shade FINISHED", 0) >= 60, counts
    assert counts.get("live ok", 0) >= 30, counts
    assert sum(v for k, v in counts.items() if k.startswith("shade reported")) >= 60, counts
    for what in ("gloss read", "frame change", "saved and reloaded", "fit_roughness FINISHED",
                 "from_principled FINISHED", "undo", "panels drawn"):
        assert counts.get(what, 0) >= 3, (what, counts)
