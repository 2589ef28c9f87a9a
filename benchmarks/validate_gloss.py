"""Accuracy check of the virtual glossmeter (not part of the test suite; a few seconds).

1. Default readings (tol = 0.05 GU) against references at tol = 1e-4 GU, for 20/60/85 degrees,
   Beckmann and GGX, roughness 1e-5..2 (one lobe n = 1.567 over diffuse 0.3): worst true error and
   how often it exceeded the stated error.
2. Where the mirror image of the source straddles a receptor edge (tilted specimen, small
   receptor): the two lobe formulations ('aperture', 'half_vector') against each other.
3. Tables: gloss at 20/60/85 degrees and haze of a 90 x 90 x 180 table (MERL's resolution) of a
   Cook-Torrance lobe (Beckmann, n = 1.5, over diffuse 0.05) against the lobe itself, m = 0.01..0.5:
   the error a table's resolution adds to a reading (the integration's own is part 1's).

    python benchmarks/validate_gloss.py
"""
import math
import os
import sys

import wenv

sys.path.append(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # after PYTHONPATH
from tests.helpers import merl_files  # noqa: E402

TABLE_ROUGHNESS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5)

ROUGHNESS = (1e-5, 1e-4, 3e-4, 1e-3, 2e-3, 3e-3, 5e-3, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)


def main():
    worst, over, n = 0.0, 0, 0
    for angle in (20, 60, 85):
        gm = wenv.Glossmeter(angle=angle)
        for dist in ("beckmann", "ggx"):
            for m in ROUGHNESS:
                mat = wenv.CookTorrance(diffuse=0.3, lobes=[dict(alpha=m, ior=1.567)], distribution=dist)
                r = gm.reading(mat)
                ref = gm.reading(mat, tol=1e-4, max_evals=50_000_000)
                err = abs(r["gloss"] - ref["gloss"])
                worst = max(worst, err)
                over += err > r["error"]
                n += 1
                if err > 0.005:
                    print(f"  {angle} {dist} m={m:g}: {r['gloss']:.4f} vs {ref['gloss']:.5f}, true error {err:.4f}, "
                          f"stated {r['error']:.4f}")
    print(f"1. {n} cases at the default tol 0.05 GU: worst true error {worst:.4f} GU; "
          f"true error above the stated one in {over} cases")

    t = math.radians(0.5)
    geoms = [dict(angle=20, normal=(math.sin(t), 0.0, math.cos(t))), dict(angle=20, receptor=(0.5, 2.0)),
             dict(angle=85, normal=(-math.sin(t), 0.0, math.cos(t))), dict(angle=60, normal=(0.0, math.sin(4 * t), math.cos(4 * t)))]
    worst = 0.0
    for kw in geoms:
        gm = wenv.Glossmeter(**kw)
        for dist in ("beckmann", "ggx"):
            for m in (1e-5, 1e-4, 1e-3, 3e-3):
                mat = wenv.CookTorrance(lobes=[dict(alpha=m, ior=1.5)], distribution=dist)
                a = gm.reading(mat, method="aperture", tol=0.002, max_evals=50_000_000)["gloss"]
                h = gm.reading(mat, method="half_vector", tol=0.002, max_evals=50_000_000)["gloss"]
                auto = gm.measure(mat)
                worst = max(worst, abs(a - h), abs(auto - h))
    print(f"2. straddling geometries: aperture vs half-vector vs default reading differ by at most {worst:.4f} GU")

    print("3. a 90 x 90 x 180 table against its Cook-Torrance lobe (GU at 20 / 60 / 85, haze HU):")
    for m in TABLE_ROUGHNESS:
        lobe = wenv.CookTorrance(diffuse=0.05, lobes=[dict(alpha=m, ior=1.5)])
        table = wenv.Tabulated(merl_files.table_of({"brdf": "cook_torrance", "roughness": m, "diffuse": [0.05] * 3}))
        want = wenv.gloss(lobe, (20, 60, 85)) + (wenv.haze(lobe),)
        got = wenv.gloss(table, (20, 60, 85)) + (wenv.haze(table),)
        cells = "  ".join(f"{g:8.3f} vs {w:8.3f} ({100 * (g - w) / w:+.2f} %)" for g, w in zip(got, want))
        print(f"  m = {m:<5g} {cells}")


if __name__ == "__main__":
    main()
