"""Gloss of every material in a .blend, read by the add-on's virtual glossmeter: 20, 60 and 85
degree readings, the geometry an instrument would report, written to CSV.

    python examples/addon_gloss_sweep.py scene.blend [--from-principled] [--out out/gloss.csv]
    python examples/addon_gloss_sweep.py              # builds and saves a demo .blend first, next to --out

Materials whose wenv settings were never set take them from their Principled BSDF (as the add-on
does on first use); --from-principled refills every material that way.  The readings run on
wenv_sweep, each in a Blender process of the sweep's: --workers of them on this machine, or on a
Dask cluster's workers (--scheduler tcp://host:8786); each is kept in OUT.jsonl as it comes, so
running again resumes an interrupted sweep.
"""
import argparse
import concurrent.futures
import csv
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import compat, gloss, materials  # noqa: E402
import wenv_sweep  # noqa: E402

OUT = os.path.join(ROOT, "out")


def demo_blend(path):
    """Paints from matte to mirror-like, a metal and a coated paint, as Principled BSDFs."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    specs = [("matte", 0.9, 0.0, 0.0), ("eggshell", 0.55, 0.0, 0.0), ("satin", 0.35, 0.0, 0.0),
             ("semi-gloss", 0.2, 0.0, 0.0), ("gloss", 0.1, 0.0, 0.0), ("high gloss", 0.03, 0.0, 0.0),
             ("brushed steel", 0.3, 1.0, 0.0), ("car paint", 0.4, 0.0, 1.0)]
    for name, roughness, metallic, coat in specs:
        mat = compat.new_node_material(name)
        node = mat.node_tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = (0.6, 0.6, 0.62, 1) if metallic else (0.4, 0.05, 0.03, 1)
        node.inputs["Roughness"].default_value = roughness
        node.inputs["Metallic"].default_value = metallic
        node.inputs["Coat Weight"].default_value = coat
        node.inputs["Coat Roughness"].default_value = 0.02
        mat.use_fake_user = True
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return path


def read_gloss(blend, material, from_principled):
    """One job, in a Blender of the sweep's: the material's readings (the .blend opened once per
    Blender process)."""
    if not hasattr(bpy.types.Material, "wenv"):
        addon.register()
    if bpy.data.filepath != blend:
        bpy.ops.wm.open_mainfile(filepath=blend)
    mat = bpy.data.materials[material]
    notes = materials.fill_from_principled(mat) if from_principled else materials.ensure_material_settings(mat)
    st = mat.wenv
    g = (st.gloss_20, st.gloss_60, st.gloss_85)
    return {"material": mat.name, "model": st.model, "lobes": len(st.lobes),
            "alpha": ";".join(f"{l.alpha:.4g}" for l in st.lobes),
            "gloss_20": f"{g[0]:.2f}", "gloss_60": f"{g[1]:.2f}", "gloss_85": f"{g[2]:.2f}",
            "instrument_geometry": gloss.instrument_geometry(g[1]), "notes": " / ".join(notes)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("blend", nargs="?", help=".blend file (default: a demo file written next to --out)")
    ap.add_argument("--from-principled", action="store_true", help="refill every material from its Principled BSDF")
    ap.add_argument("--workers", type=int, default=2, help="Blender processes on this machine")
    ap.add_argument("--scheduler", help="a Dask scheduler's address: run the jobs on its cluster")
    ap.add_argument("--out", default=os.path.join(OUT, "addon_gloss.csv"))
    args = ap.parse_args()
    addon.register()
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    path = os.path.abspath(args.blend or demo_blend(os.path.join(os.path.dirname(os.path.abspath(args.out)),
                                                                 "gloss_materials.blend")))
    bpy.ops.wm.open_mainfile(filepath=path)
    jobs = [{"blend": path, "material": mat.name, "from_principled": args.from_principled}
            for mat in bpy.data.materials if not mat.is_grease_pencil]
    if args.scheduler:
        from dask.distributed import Client
        executor = Client(args.scheduler).get_executor()
    else:  # each thread drives a Blender process of its own (in_blender)
        executor = concurrent.futures.ThreadPoolExecutor(args.workers)
    with executor:  # the readings are kept as they come: run again to resume
        report = wenv_sweep.run(jobs, wenv_sweep.in_blender(read_gloss), executor=executor, progress=None,
                                results=os.path.splitext(args.out)[0] + ".jsonl")
    rows = [report.results[wenv_sweep.key(job)] for job in jobs if wenv_sweep.key(job) in report.results]
    for row in rows:
        print(f"{row['material']:>16}: {row['gloss_20']:>7} {row['gloss_60']:>7} {row['gloss_85']:>7} GU  "
              f"(instrument: {row['instrument_geometry']} deg)")
    for job, error in report.failed:
        print(f"failed: {job['material']}: {error}")
    with open(args.out, "w", newline="") as fp:
        w = csv.DictWriter(fp, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("wrote", args.out)
    return 1 if report.failed else 0


if __name__ == "__main__":
    sys.exit(main())
