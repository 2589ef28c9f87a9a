"""The add-on's headless example scripts (examples/) and its benchmark (benchmarks/bench_addon.py)
run and write what they promise (small settings).  They are run as scripts, never imported."""
import csv
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(tmp_path, *args):
    env = dict(os.environ, WENV_CACHE_DIR=str(tmp_path))
    proc = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc.stdout


def test_shade_sweep_writes_csv(tmp_path):
    run(tmp_path, "examples/addon_shade_sweep.py", "--roughness", "0.05", "0.4", "--rotation", "0", "180",
        "--out", str(tmp_path / "sweep"))
    rows = list(csv.DictReader(open(tmp_path / "sweep" / "sweep.csv")))
    assert [(r["roughness"], r["rotation_deg"]) for r in rows] == [("0.05", "0"), ("0.05", "180"),
                                                                   ("0.4", "0"), ("0.4", "180")]
    means = [float(r["mean_r"]) for r in rows]
    assert all(0 < m < 1 for m in means)
    assert means[0] != means[1]  # turning the World changes the picture


def test_gloss_sweep_reads_every_material(tmp_path):
    out = tmp_path / "gloss.csv"
    blend = tmp_path / "gloss_materials.blend"  # without a .blend the script builds one next to --out
    run(tmp_path, "examples/addon_gloss_sweep.py", "--out", str(tmp_path / "demo_gloss.csv"))
    assert blend.exists()
    run(tmp_path, "examples/addon_gloss_sweep.py", str(blend), "--out", str(out))
    rows = {r["material"]: r for r in csv.DictReader(open(out))}
    assert {"matte", "satin", "gloss", "high gloss", "car paint", "brushed steel"} <= set(rows)
    g60 = {name: float(r["gloss_60"]) for name, r in rows.items()}
    assert g60["matte"] < g60["satin"] < g60["gloss"]  # smoother reads higher
    assert rows["matte"]["instrument_geometry"] == "85" and rows["high gloss"]["instrument_geometry"] == "20"


def test_bench_runs(tmp_path):
    path = tmp_path / "bench.json"
    run(tmp_path, "benchmarks/bench_addon.py", "--quality", "draft", "--levels", "1", "--repeats", "2",
        "--json", str(path))
    result = json.load(open(path))["results"][0]
    assert result["vertices"] == 2012  # Suzanne subdivided once
    assert all(v > 0 for v in result["median_ms"].values())


def test_demo_runs_and_prints_what_the_readme_shows(tmp_path):
    """The main job (README's first command) at a small size: it runs, writes its picture, its wenv
    colours agree with Cycles' on average, and its gloss line -- which depends on no render -- is the
    README's."""
    picture = tmp_path / "demo.png"
    out = run(tmp_path, "examples/demo.py", "--size", "64", "--samples", "8", "--out", str(picture))
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    ratio = float(out.split("mean radiance ratio")[1].split()[0].rstrip("),"))
    assert 0.9 < ratio < 1.1  # her shadows and bounce light: as bright as Cycles on average
    assert "EEVEE" in out
    gloss = next(line.strip() for line in out.splitlines() if line.strip().startswith("gloss:"))
    readme = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    assert "\n  " + gloss + "\n" in readme
