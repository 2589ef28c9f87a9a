"""Seed corpus for the fuzz targets, generated here so that no binary file is stored: small valid
files of each kind every reader accepts, written by the project's own test writers, Blender's
OpenEXR codecs (bpy) and a tiny Shader's cache.

    python tests/fuzz/seeds.py OUT_DIR      # writes OUT_DIR/<target>/*, as tests/fuzz/run.py does
"""
import os
import struct
import sys
import tempfile
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
for p in (os.path.join(ROOT, "tests"), ROOT):
    if p not in sys.path:
        sys.path.insert(0, p)


def exr_seeds(out):
    from test_envmap import write_exr

    rng = np.random.default_rng(1)
    img = rng.uniform(0, 8, (6, 8, 4)).astype(np.float32)
    variants = {
        "scan_float_rgb": dict(pixel_type="float", channels="RGB"),
        "scan_half_rgba": dict(pixel_type="half", channels="RGBA"),
        "scan_float_y": dict(pixel_type="float", channels="Y"),
        "scan_half_ya": dict(pixel_type="half", channels="YA"),
        "tiled_float_rgba": dict(pixel_type="float", channels="RGBA", tile=(4, 4)),
        "tiled_half_rgb": dict(pixel_type="half", channels="RGB", tile=(3, 5)),
        "tiled_half_y": dict(pixel_type="half", channels="Y", tile=(8, 2)),
        "offset_window": dict(pixel_type="float", channels="RGB", origin=(-3, 5)),
    }
    for name, kw in variants.items():
        write_exr(os.path.join(out, name + ".exr"), img[..., :len(kw["channels"])], **kw)
    # every compression Blender writes (OpenEXRCore decodes them, but DWAA/DWAB go through OpenEXR's
    # C++ library), half and float, through Blender's own writer
    import bpy

    h, w = 6, 8
    pixels = np.concatenate([img[..., :3], np.ones((h, w, 1), np.float32)], -1)
    image = bpy.data.images.new("wenv_fuzz_seed", w, h, float_buffer=True, alpha=True)
    image.pixels.foreach_set(pixels[::-1].ravel())
    scene = bpy.context.scene
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    for codec in ("ZIP", "ZIPS", "PIZ", "RLE", "PXR24", "DWAA", "DWAB"):
        for depth, mode in (("16", "RGBA"), ("32", "RGB")):
            settings.color_mode, settings.color_depth, settings.exr_codec = mode, depth, codec
            image.save_render(os.path.join(out, f"blender_{codec.lower()}_{depth}.exr"), scene=scene)
    bpy.data.images.remove(image)


def rgbe_seeds(out):
    from test_envmap import rgbe_encode, write_hdr

    rng = np.random.default_rng(2)
    q = rgbe_encode(rng.uniform(0, 4, (4, 12, 3)))
    q[1, 3:9] = q[1, 3]  # runs for the run-length coder
    write_hdr(os.path.join(out, "rle.hdr"), q, rle=True)
    write_hdr(os.path.join(out, "flat.hdr"), q[:3, :5], rle=False)
    write_hdr(os.path.join(out, "crlf.hdr"), q[:2, :8], rle=True,
              header=b"#?RGBE\r\nFORMAT=32-bit_rle_rgbe\r\nEXPOSURE=2.0\r\n\r\n")
    # old-style run lengths: (1, 1, 1, n) repeats the previous pixel n times, and each run right after
    # another counts 256 times more: 1 literal + 43 + 1 * 256 = 300 pixels per row
    row = bytes(q[0, 0]) + b"\x01\x01\x01\x2b" + b"\x01\x01\x01\x01"
    with open(os.path.join(out, "old_rle.hdr"), "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 300\n" + row + row)


def merl_seeds(out):
    from tests.helpers.merl_files import merl_bytes

    rng = np.random.default_rng(3)
    shapes = [(2, 2, 2), (3, 4, 5), (4, 2, 6)]
    for k, shape in enumerate(shapes):
        table = rng.uniform(0, 0.3, shape + (3,))
        unmeasured = None
        if k == 1:
            unmeasured = rng.uniform(size=shape) < 0.3
        if k == 2:
            unmeasured = np.zeros(shape, bool)
            unmeasured[1] = True  # a whole theta_h with nothing measured
            unmeasured[3, :, 2] = True
        with open(os.path.join(out, "merl_%dx%dx%d.binary" % shape), "wb") as f:
            f.write(merl_bytes(table, unmeasured))


def matrix_cache_seeds(out):
    import wenv

    env = wenv.Environment(np.random.default_rng(4).uniform(0, 1, (8, 16, 3)).astype(np.float32))
    mat = wenv.CookTorrance(diffuse=(0.2, 0.2, 0.2), lobes=[{"specular": (1, 1, 1), "alpha": 0.3, "ior": 1.5}])
    settings = [dict(normals=2, matrix_epsilon=1e-3), dict(normals=4, matrix_epsilon=0.0),
                dict(normals=2, matrix_epsilon=0.5), {"global": 8, "local": 8, "normals": 2, "coefficients": 64}]
    with tempfile.TemporaryDirectory() as cache:
        for k, s in enumerate(settings):
            quality = {"global": 4, "local": 4, "views": 2, "coefficients": 16, "lights": 0, **s}
            wenv.Shader(env, mat, quality=quality, method="rotation", cache_dir=cache)
            (name,) = [n for n in os.listdir(cache) if n.endswith(".bin")]
            os.replace(os.path.join(cache, name), os.path.join(out, "cache_%d.bin" % k))


# ------------------------------------------------------------------ regressions
# Inputs that once crashed a target or broke a reader's promise, rebuilt here and kept in the seeds,
# so every run (and the test suite's short one) replays them first.


def exr_regressions(out):
    from test_envmap import exr_header_length, exr_with_chunks, write_exr

    path = os.path.join(out, "regress_window.exr")
    write_exr(path, np.ones((6, 8, 3), np.float32))
    data = open(path, "rb").read()
    window = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    # a window of 1023 x 1025 pixels over a file of 6 rows: its missing chunks found before decoding
    with open(path, "wb") as f:
        f.write(data[:window] + struct.pack("<iiii", 0, 0, 1022, 1024) + data[window + 16:])
    # uncompressed chunks of 8 pixels under a window 800 wide: OpenEXRCore 3.1 decodes them to nothing
    with open(os.path.join(out, "regress_short_chunks.exr"), "wb") as f:
        f.write(exr_with_chunks(data, (800, 6), 0, 1, data[-96:]))
    # DWAA (OpenEXR's C++ library decodes it) with an attribute claiming 2 GB that OpenEXRCore steps over
    write_exr(path, np.ones((4, 8, 3), np.float32), pixel_type="half")
    data = open(path, "rb").read()
    c = data.index(b"compression\0compression\0") + len(b"compression\0compression\0") + 4
    data = data[:c] + b"\x08" + data[c + 1:]
    head = exr_header_length(data)
    bad = b"note\0string\0" + struct.pack("<i", 2**31 - 1)
    (offset,) = struct.unpack("<Q", data[head:head + 8])
    with open(os.path.join(out, "regress_dwa_header.exr"), "wb") as f:
        f.write(data[:head - 1] + bad + b"\0" + struct.pack("<Q", offset + len(bad)) + data[head + 8:])


def merl_regressions(out):
    from tests.helpers.merl_files import merl_bytes

    table = np.full((2, 3, 4, 3), 0.01)
    table[1, 2, 3, 1] = 1e300  # finite as a double, infinite as a float
    with open(os.path.join(out, "regress_past_float.binary"), "wb") as f:
        f.write(merl_bytes(table))
    table[1, 2, 3, 1] = 3.402e38  # a float (FLT_MAX is 3.4028e38), past the 3.4e38 the target once took for the largest
    with open(os.path.join(out, "regress_near_float_max.binary"), "wb") as f:
        f.write(merl_bytes(table))


def matrix_cache_regressions(out):
    # valid CRCs over a block table whose first block claims 40 GB (80 GB inflated) in a file of 144 bytes
    ns = 4
    head = b"WENVROT\0" + struct.pack("<II", 3, 0) + struct.pack("<QQQd", 512, 256, 2, 1e-3)
    table = struct.pack("<QQII", 40 << 30, 80 << 30, 0, 0) + struct.pack("<QQII", 8, 8, 0, 0) * (ns - 1)
    crc = zlib.crc32(table, zlib.crc32(head))
    with open(os.path.join(out, "regress_block_sizes.bin"), "wb") as f:
        f.write(head[:12] + struct.pack("<I", crc) + head[16:] + table)


SEEDS = {"exr": exr_seeds, "rgbe": rgbe_seeds, "merl": merl_seeds, "matrix_cache": matrix_cache_seeds}
REGRESSIONS = {"exr": exr_regressions, "merl": merl_regressions, "matrix_cache": matrix_cache_regressions}


def write_seeds(out_dir, targets=None):
    """Writes each target's seeds to out_dir/<target>/ (emptied first)."""
    for target in targets or SEEDS:
        d = os.path.join(out_dir, target)
        os.makedirs(d, exist_ok=True)
        for name in os.listdir(d):
            os.remove(os.path.join(d, name))
        SEEDS[target](d)
        if target in REGRESSIONS:
            REGRESSIONS[target](d)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    write_seeds(sys.argv[1])
    for target in SEEDS:
        print(target, len(os.listdir(os.path.join(sys.argv[1], target))), "seeds")
