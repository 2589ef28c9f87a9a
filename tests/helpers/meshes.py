"""Small meshes the shadow tests build scenes from: boxes, squares, UV spheres, and their union."""
import math

import numpy as np


def box(lo, hi):
    """Corners (8, 3) and triangles (12, 3) of an axis-aligned box, faces outward."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c_, d in quads for t in ((a, b, c_), (a, c_, d))]
    return c, np.array(tris)


def square(half, z, x=0.0, y=0.0):
    """A square of half-side `half` centred on (x, y) at height z (two triangles)."""
    p = np.array([[x - half, y - half, z], [x + half, y - half, z], [x + half, y + half, z], [x - half, y + half, z]],
                 np.float32)
    return p, np.array([[0, 1, 2], [0, 2, 3]])


def merged(*parts):
    positions, triangles, base = [], [], 0
    for p, t in parts:
        positions.append(p)
        triangles.append(t + base)
        base += len(p)
    return np.vstack(positions).astype(np.float32), np.vstack(triangles)


def uv_sphere(rings=24, segments=48, radius=1.0):
    """A closed UV sphere: positions (also its normals) and triangles."""
    v = [[0.0, 0.0, 1.0]]
    for r in range(1, rings):
        t = math.pi * r / rings
        v += [[math.sin(t) * math.cos(2 * math.pi * s / segments), math.sin(t) * math.sin(2 * math.pi * s / segments),
               math.cos(t)] for s in range(segments)]
    v.append([0.0, 0.0, -1.0])
    f = [[0, 1 + s, 1 + (s + 1) % segments] for s in range(segments)]
    for r in range(rings - 2):
        for s in range(segments):
            a, b = 1 + r * segments + s, 1 + r * segments + (s + 1) % segments
            f += [[a, a + segments, b + segments], [a, b + segments, b]]
    last = len(v) - 1
    f += [[last, 1 + (rings - 2) * segments + (s + 1) % segments, 1 + (rings - 2) * segments + s]
          for s in range(segments)]
    return np.array(v, np.float32) * radius, np.array(f)
