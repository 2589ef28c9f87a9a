"""Gloss of every material in a .blend, read by the add-on's virtual glossmeter: 20, 60 and 85
degree readings, the geometry an instrument would report, written to CSV.

    python examples/addon_gloss_sweep.py scene.blend [--from-principled] [--out out/gloss.csv]
    python examples/addon_gloss_sweep.py              # builds and saves a demo .blend first, next to --out

Materials whose wenv settings were never set take them from their Principled BSDF (as the add-on
does on first use); --from-principled refills every material that way.
"""
import argparse
import csv
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import compat, gloss, materials  # noqa: E402

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


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("blend", nargs="?", help=".blend file (default: a demo file written next to --out)")
    ap.add_argument("--from-principled", action="store_true", help="refill every material from its Principled BSDF")
    ap.add_argument("--out", default=os.path.join(OUT, "addon_gloss.csv"))
    args = ap.parse_args()
    addon.register()
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    path = args.blend or demo_blend(os.path.join(os.path.dirname(os.path.abspath(args.out)), "gloss_materials.blend"))
    bpy.ops.wm.open_mainfile(filepath=path)

    rows = []
    for mat in bpy.data.materials:
        if mat.is_grease_pencil:
            continue
        notes = materials.fill_from_principled(mat) if args.from_principled else materials.ensure_material_settings(mat)
        st = mat.wenv
        g = (st.gloss_20, st.gloss_60, st.gloss_85)
        rows.append({"material": mat.name, "model": st.model, "lobes": len(st.lobes),
                     "alpha": ";".join(f"{l.alpha:.4g}" for l in st.lobes),
                     "gloss_20": f"{g[0]:.2f}", "gloss_60": f"{g[1]:.2f}", "gloss_85": f"{g[2]:.2f}",
                     "instrument_geometry": gloss.instrument_geometry(g[1]), "notes": " / ".join(notes)})
        print(f"{mat.name:>16}: {g[0]:7.2f} {g[1]:7.2f} {g[2]:7.2f} GU  (instrument: "
              f"{gloss.instrument_geometry(g[1])} deg)")
    with open(args.out, "w", newline="") as fp:
        w = csv.DictWriter(fp, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
