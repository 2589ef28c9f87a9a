"""What the Blender add-on's live mode shows after a change, and when: Suzanne subdivided to ~126k
vertices under Blender's "sunset" HDRI, seen from the scene camera (every vertex shaded), one GGX
lobe of roughness 0.45 (m = 0.2), 2 threads.  For a view change, a World rotation, a new World
image (two HDRIs in turn, their pixels read once), a material edit (the roughness nudged) and the
last edit undone and redone (materials the shader keeps), the median time from the change to the first colours written and to the colours of the quality set,
with Draft While Remaking on and off, side by side in one run.  Then a view change with a second
mesh of another material beside her (a UV sphere of 32k vertices): the shader keeps both
materials, so neither is made again.

The session is ticked every millisecond (the live operator's timer ticks every 50 ms, which adds up
to that much to each figure in Blender).  Prints a table and writes out/bench_live.json.

    python benchmarks/bench_live.py [--quality default] [--repeats 5] [--threads 2]
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402
import wenv  # noqa: E402

import addon  # noqa: E402
from addon import engine, live  # noqa: E402
from bench_addon import build_scene  # noqa: E402
from measure import OUT  # noqa: E402
from tests.helpers.measure import bundled_hdri  # noqa: E402


def settle(session, chosen, timeout=120.0):
    """Ticks until the quality set is shown.  Returns (seconds to the first colours written,
    seconds to the quality set's, the quality first shown)."""
    ctx = bpy.context
    t0 = time.perf_counter()
    first = shown_first = None
    while time.perf_counter() - t0 < timeout:
        if session.tick(ctx):
            now = time.perf_counter() - t0
            if first is None:
                first, shown_first = now, session.shown
            if session.shown == chosen:
                return first, now, shown_first
        time.sleep(0.001)
    raise SystemExit(f"no {chosen} colours within {timeout} s: {session.last_error}")


def bench(quality, repeats, preview):
    scene, obj = build_scene(4, quality)
    scene.wenv.view_source = "CAMERA"
    scene.wenv.refine_at_rest = False  # the figures are the quality set's; refining is bench_interactive's
    scene.wenv.preview_changes = preview
    tree = scene.world.node_tree
    env_node = tree.nodes["Environment Texture"]
    mapping = tree.nodes.new("ShaderNodeMapping")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env_node.inputs["Vector"])
    images = [env_node.image, bpy.data.images.load(bundled_hdri("forest"))]
    lobe = obj.data.materials[0].wenv.lobes[0]
    lobe.roughness = 0.45
    cam = scene.camera
    engine.shaders.clear()
    engine.shaders.get(quality)
    engine.shaders.get(engine.PREVIEW_QUALITY)  # what the live operator builds when it starts
    session = live.LiveSession([obj.name])
    settle(session, quality)
    for image in images[::-1]:  # each image's pixels read once, as when the user has tried both
        env_node.image = image
        settle(session, quality)

    def view(i):
        a = math.radians(40 + 3 * i)
        cam.location = (7.4 * math.cos(a), -7.4 * math.sin(a), 5.0)

    def rotation(i):
        mapping.inputs["Rotation"].default_value[2] = 0.2 * (i + 1)

    def image(i):
        env_node.image = images[(i + 1) % 2]

    def material(i):
        lobe.roughness = 0.46 + 0.01 * i

    def material_back(i):  # the last edit undone and redone: materials the shader keeps
        lobe.roughness = 0.46 + 0.01 * (repeats - 2 + i % 2)

    def timed(session, change):
        """Medians over `repeats` changes (change(i), then settle)."""
        runs = []
        for i in range(repeats):
            change(i)
            runs.append(settle(session, quality))
        return {"first_ms": statistics.median(r[0] for r in runs) * 1e3,
                "quality_ms": statistics.median(r[1] for r in runs) * 1e3,
                "first_shown": sorted({r[2] for r in runs})}

    out = {}
    for name, change in (("view change", view), ("World rotation", rotation), ("new image", image),
                         ("material edit", material), ("material edit undone", material_back)):
        out[name] = timed(session, change)
    # a second mesh of another material: the shader keeps both, so a view change makes neither again
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, location=(2.5, 0.0, 0.0))
    ball = bpy.context.object
    other = bpy.data.materials.new("glaze")
    other.wenv.model = "COOK_TORRANCE"
    other.wenv.lobes.add().roughness = 0.3
    other.wenv.initialized = True
    ball.data.materials.append(other)
    session.stop()
    session = live.LiveSession([obj.name, ball.name])
    settle(session, quality)
    out["view change, two materials"] = timed(session, lambda i: view(i + repeats))
    out["view change, two materials"]["vertices"] = len(obj.data.vertices) + len(ball.data.vertices)
    session.stop()
    return len(obj.data.vertices), out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quality", default="default", choices=[q for q in engine.QUALITIES if q != engine.PREVIEW_QUALITY])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", default=os.path.join(OUT, "bench_live.json"))
    args = ap.parse_args()
    wenv.set_num_threads(args.threads)
    addon.register()
    results = {}
    for preview in (True, False):
        n, results["on" if preview else "off"] = bench(args.quality, args.repeats, preview)
    print(f"live mode at {args.quality}, {n} vertices, {args.threads} threads, median of {args.repeats} changes (ms): "
          f"first colours (quality shown) / {args.quality}'s colours")
    print(f"{'change':28s} {'Draft While Remaking on':>34s} {'off':>16s}")
    for case in results["on"]:
        on, off = results["on"][case], results["off"][case]
        print(f"{case:28s} {on['first_ms']:9.0f} ({'/'.join(on['first_shown']):>7s}) / {on['quality_ms']:6.0f}"
              f" {off['first_ms']:9.0f} / {off['quality_ms']:6.0f}")
    os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
    with open(args.json, "w") as fp:
        json.dump({"quality": args.quality, "threads": args.threads, "repeats": args.repeats, "vertices": n,
                   "results": results}, fp, indent=2)
    print("wrote", args.json)
    addon.unregister()


if __name__ == "__main__":
    main()
