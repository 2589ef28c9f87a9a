"""wenv.Environment / wenv.load_environment: projections, solid angles, lookup, file readers, and the
orientation check against Cycles."""
import gc
import math
import os
import struct

import numpy as np
import pytest

import wenv
from conftest import HDRI_NAMES, hdri_path

FOUR_PI = 4.0 * math.pi


# ------------------------------------------------------------------------------------------------
# helpers


def rot_z(r):
    c, s = math.cos(r), math.sin(r)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def random_dirs(n, seed=0):
    return unit(np.random.default_rng(seed).normal(size=(n, 3)))


def smooth_field(d):
    """A smooth, asymmetric RGB function of direction (no mirror or rotation symmetry)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([1.0 + 0.5 * x + 0.2 * y * z, 1.0 + 0.4 * y + 0.1 * x * x, 1.0 + 0.3 * z - 0.2 * x * y], -1)


def equirect_centres(h, w):
    """World directions of the pixel centres of an equirect image (docs/ARCHITECTURE.md §3.4)."""
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    phi = np.pi * (1.0 - 2.0 * u)[None, :]
    lat = np.pi * (v - 0.5)[:, None]
    return np.stack(np.broadcast_arrays(np.cos(lat) * np.cos(phi), np.cos(lat) * np.sin(phi), np.sin(lat)), -1)


def mirrorball_centres(h, w):
    """Cycles' mirrorball_to_direction at the pixel centres; NaN outside the disk."""
    x = (2.0 * np.arange(w) + 1.0 - w) / w
    z = (h - 2.0 * np.arange(h) - 1.0) / h
    X, Z = np.meshgrid(x, z)
    r2 = X * X + Z * Z
    k = np.sqrt(np.where(r2 <= 1.0, 1.0 - r2, np.nan))
    d = np.stack([X, -k, Z], -1)
    return 2.0 * k[..., None] * d - np.array([0.0, -1.0, 0.0])


# The documented cube cross layout (envmap.h): face -> (cell col, row, centre, right, down).
HCROSS = {
    "+X": (1, 1, (1, 0, 0), (0, -1, 0), (0, 0, -1)),
    "-X": (3, 1, (-1, 0, 0), (0, 1, 0), (0, 0, -1)),
    "+Y": (0, 1, (0, 1, 0), (1, 0, 0), (0, 0, -1)),
    "-Y": (2, 1, (0, -1, 0), (-1, 0, 0), (0, 0, -1)),
    "+Z": (1, 0, (0, 0, 1), (0, -1, 0), (1, 0, 0)),
    "-Z": (1, 2, (0, 0, -1), (0, -1, 0), (-1, 0, 0)),
}
VCROSS = dict(HCROSS, **{"-X": (1, 3, (-1, 0, 0), (0, -1, 0), (0, 0, 1))})


def cube_cross_image(n, vertical, field):
    layout = VCROSS if vertical else HCROSS
    h, w = (4 * n, 3 * n) if vertical else (3 * n, 4 * n)
    img = np.zeros((h, w, 3))
    t = (2.0 * np.arange(n) + 1.0 - n) / n
    S, T = np.meshgrid(t, t)
    for col, row, c, r, dn in layout.values():
        d = unit(np.array(c) + S[..., None] * np.array(r) + T[..., None] * np.array(dn))
        img[row * n:(row + 1) * n, col * n:(col + 1) * n] = field(d)
    return img


# --- minimal file writers (uncompressed OpenEXR, Radiance RGBE) ---------------------------------


def write_exr(path, pixels, pixel_type="float", channels="RGB", tile=None, origin=(0, 0)):
    """Uncompressed OpenEXR, scanline or one-level tiled; pixels (H, W, C), row 0 the top."""
    h, w, _ = pixels.shape
    order = sorted(range(len(channels)), key=lambda i: channels[i])  # channels are stored sorted
    code, dtype = {"half": (1, np.float16), "float": (2, np.float32)}[pixel_type]
    chlist = b"".join(channels[i].encode() + b"\0" + struct.pack("<iB3xii", code, 0, 1, 1) for i in order) + b"\0"
    x0, y0 = origin
    box = struct.pack("<iiii", x0, y0, x0 + w - 1, y0 + h - 1)
    attrs = [("channels", "chlist", chlist), ("compression", "compression", b"\0"), ("dataWindow", "box2i", box),
             ("displayWindow", "box2i", box), ("lineOrder", "lineOrder", b"\0"),
             ("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
             ("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0)),
             ("screenWindowWidth", "float", struct.pack("<f", 1.0))]
    if tile:
        attrs.append(("tiles", "tiledesc", struct.pack("<IIB", tile[0], tile[1], 0)))
    head = b"\x76\x2f\x31\x01" + struct.pack("<I", 2 | (0x200 if tile else 0))
    head += b"".join(n.encode() + b"\0" + t.encode() + b"\0" + struct.pack("<i", len(v)) + v for n, t, v in attrs)
    head += b"\0"
    data = pixels.astype(dtype)
    chunks = []
    if not tile:
        for r in range(h):
            body = b"".join(data[r, :, i].tobytes() for i in order)
            chunks.append(struct.pack("<ii", y0 + r, len(body)) + body)
    else:
        tw, th = tile
        for ty in range((h + th - 1) // th):
            for tx in range((w + tw - 1) // tw):
                block = data[ty * th:(ty + 1) * th, tx * tw:(tx + 1) * tw]
                body = b"".join(block[r, :, i].tobytes() for r in range(block.shape[0]) for i in order)
                chunks.append(struct.pack("<iiiii", tx, ty, 0, 0, len(body)) + body)
    offset = len(head) + 8 * len(chunks)
    table = b""
    for c in chunks:
        table += struct.pack("<Q", offset)
        offset += len(c)
    with open(path, "wb") as f:
        f.write(head + table + b"".join(chunks))


def exr_header_length(data):
    pos = 8
    while data[pos] != 0:
        pos = data.index(b"\0", pos) + 1
        pos = data.index(b"\0", pos) + 1
        pos += 4 + struct.unpack("<i", data[pos:pos + 4])[0]
    return pos + 1


def rgbe_encode(rgb):
    m = rgb.max(-1)
    mant, exp = np.frexp(m)
    ok = m > 1e-32
    scale = np.where(ok, mant * 256.0 / np.where(ok, m, 1.0), 0.0)
    out = np.zeros(rgb.shape[:2] + (4,), np.uint8)
    out[..., :3] = np.clip(rgb * scale[..., None], 0, 255).astype(np.uint8)
    out[..., 3] = np.where(ok, exp + 128, 0)
    return out


def rgbe_decode(q):
    """mantissa * 2^(e - 136), as Blender (OpenImageIO) and stb_image decode RGBE."""
    e = q[..., 3].astype(np.int64)
    f = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return (q[..., :3] * f[..., None]).astype(np.float32)


def rle_channel(b):
    out, i, n = bytearray(), 0, len(b)
    while i < n:
        j = i
        while j < n and j - i < 127 and b[j] == b[i]:
            j += 1
        if j - i >= 3:
            out += bytes([128 + j - i, b[i]])
            i = j
            continue
        j = i
        while j < n and j - i < 128 and not (j + 2 < n and b[j] == b[j + 1] == b[j + 2]):
            j += 1
        out += bytes([j - i]) + bytes(b[i:j])
        i = j
    return bytes(out)


def write_hdr(path, q, rle=True, header=b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\n\n", res=None):
    h, w, _ = q.shape
    body = bytearray(header + (res or b"-Y %d +X %d\n" % (h, w)))
    for row in q:
        if rle:
            body += bytes([2, 2, w >> 8, w & 255])
            for ch in range(4):
                body += rle_channel(row[:, ch].tobytes())
        else:
            body += row.tobytes()
    with open(path, "wb") as f:
        f.write(bytes(body))


# ------------------------------------------------------------------------------------------------
# conventions


def test_equirect_convention():
    h, w = 16, 32
    col, row = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    img = np.stack([col, row, np.ones_like(col)], -1)  # pixel value = (column, row, 1)
    env = wenv.Environment(img)
    look = lambda d: env.lookup(f32(d))
    # +X at the image centre, +Y at u = 0.25, -Y at u = 0.75, horizon between the middle rows
    np.testing.assert_allclose(look([1, 0, 0]), [w / 2 - 0.5, h / 2 - 0.5, 1], atol=1e-5)
    np.testing.assert_allclose(look([0, 1, 0]), [w / 4 - 0.5, h / 2 - 0.5, 1], atol=1e-5)
    np.testing.assert_allclose(look([0, -1, 0]), [3 * w / 4 - 0.5, h / 2 - 0.5, 1], atol=1e-5)
    # +Z reads the top row, -Z the bottom row
    assert look([0, 0, 1])[1] == pytest.approx(0.0, abs=1e-6)
    assert look([0, 0, -1])[1] == pytest.approx(h - 1, abs=1e-6)
    # 45 degrees up at +X: v = 0.75, a quarter of the way down
    np.testing.assert_allclose(look([1, 0, 1]), [w / 2 - 0.5, h / 4 - 0.5, 1], atol=1e-5)
    # rotation pi/2 makes +X see what +Y saw; strength multiplies
    rot = wenv.Environment(img, rotation=math.pi / 2, strength=2.0)
    np.testing.assert_allclose(rot.lookup(f32([1, 0, 0])), 2 * look([0, 1, 0]), rtol=1e-5)
    np.testing.assert_allclose(rot.lookup(f32([0, -1, 0])), 2 * look([1, 0, 0]), rtol=1e-5)
    # general rotation: world d reads where R_z(r) d reads unrotated
    d = random_dirs(200, 1)
    r = 0.8
    np.testing.assert_allclose(env.with_transform(rotation=r).lookup(f32(d)), env.lookup(f32(d @ rot_z(r).T)),
                               atol=2e-4)


def test_equirect_lookup_matches_smooth_field():
    h, w = 256, 512
    env = wenv.Environment(f32(smooth_field(equirect_centres(h, w))))
    d = random_dirs(2000, 2)
    np.testing.assert_allclose(env.lookup(f32(d)), smooth_field(d), atol=2e-3)


def test_mirror_ball_convention():
    n = 64
    env = wenv.Environment(f32(np.nan_to_num(smooth_field(mirrorball_centres(n, n)))), projection="mirror_ball")
    # centre of the disk sees -Y; top of the disk +Z side; right-hand side +X side
    centre = (n // 2 - 1, n // 2)
    img = env.pixels
    expect_centre = img[centre[0]:centre[0] + 2, centre[1] - 1:centre[1] + 1].mean(axis=(0, 1))
    np.testing.assert_allclose(env.lookup(f32([0, -1, 0])), expect_centre, rtol=1e-5)
    d = random_dirs(3000, 3)
    d = d[d[:, 1] < 0.6]  # away from the rim (+Y), where the ball's texels stretch
    np.testing.assert_allclose(env.lookup(f32(d)), smooth_field(d), atol=2e-2)
    # the rim and exactly +Y stay finite
    assert np.all(np.isfinite(env.lookup(f32([[0, 1, 0], [1e-9, 1, 0], [0.01, 1, 0.01]]))))


@pytest.mark.parametrize("vertical", [False, True])
def test_cube_cross_faces_and_orientation(vertical):
    n = 8
    layout = VCROSS if vertical else HCROSS
    h, w = (4 * n, 3 * n) if vertical else (3 * n, 4 * n)
    img = np.zeros((h, w, 3), np.float32)
    colours = {}
    for k, (name, (col, row, *_)) in enumerate(layout.items()):
        colours[name] = np.array([k + 1, 10 * (k + 1), 100 * (k + 1)], np.float32)
        img[row * n:(row + 1) * n, col * n:(col + 1) * n] = colours[name]
    env = wenv.Environment(img, projection="cube_cross")
    axes = {"+X": [1, 0, 0], "-X": [-1, 0, 0], "+Y": [0, 1, 0], "-Y": [0, -1, 0], "+Z": [0, 0, 1], "-Z": [0, 0, -1]}
    for name, a in axes.items():
        np.testing.assert_allclose(env.lookup(f32(a)), colours[name], err_msg=name)
    # orientation inside each face: a smooth field sampled at texel centres is reproduced
    n = 64
    env = wenv.Environment(f32(cube_cross_image(n, vertical, smooth_field)), projection="cube_cross")
    d = random_dirs(3000, 4)
    np.testing.assert_allclose(env.lookup(f32(d)), smooth_field(d), atol=2e-3)
    # edges and corners (reads from the neighbouring face) stay finite and close to the field
    edges = unit(np.array([[1, 1, 0], [1, -1, 0], [-1, 1, 0], [1, 0, 1], [0, -1, -1], [1, 1, 1], [-1, -1, -1],
                           [-1, 1, 1], [1, 0.999, 0.3]], float))
    np.testing.assert_allclose(env.lookup(f32(edges)), smooth_field(edges), atol=2e-2)


def test_cube_cross_strip_agrees_with_equirect():
    """The horizontal strip +Y, +X, -Y, -X is a panorama in the same sense as an equirect image."""
    n = 32
    field = lambda d: np.stack([np.arctan2(d[..., 1], d[..., 0]) + 4.0, d[..., 2] + 2.0, np.ones(d.shape[:-1])], -1)
    cube = wenv.Environment(f32(cube_cross_image(n, False, field)), projection="cube_cross")
    # a point left of the +X face centre in the image looks towards +Y (phi > 0), as in equirect
    strip = cube.pixels[n:2 * n]
    assert strip[n // 2, n + 2, 0] > strip[n // 2, 2 * n - 3, 0]
    assert cube.lookup(f32([1, 0.3, 0]))[0] > cube.lookup(f32([1, -0.3, 0]))[0]


# ------------------------------------------------------------------------------------------------
# solid angles and samples


@pytest.mark.parametrize(
    "projection,shape",
    [("equirect", (512, 1024)), ("equirect", (7, 5)), ("equirect", (1, 1)), ("mirror_ball", (256, 256)),
     ("mirror_ball", (33, 47)), ("mirror_ball", (1, 1)), ("cube_cross", (96, 128)), ("cube_cross", (128, 96)),
     ("cube_cross", (3, 4))])
def test_solid_angles_sum_to_4pi(projection, shape):
    env = wenv.Environment(np.ones(shape + (3,), np.float32), projection=projection)
    sa = env.solid_angles()
    assert sa.shape == shape and sa.dtype == np.float64
    assert np.all(sa >= 0)
    assert sa.sum() == pytest.approx(FOUR_PI, rel=1e-6)


def test_solid_angle_formulas():
    # equirect: dphi (sin lat_top - sin lat_bottom)
    h, w = 9, 20
    sa = wenv.Environment(np.ones((h, w, 3), np.float32)).solid_angles()
    lat = np.pi / 2 - np.arange(h + 1) * np.pi / h
    np.testing.assert_allclose(sa[:, 0], 2 * np.pi / w * (np.sin(lat[:-1]) - np.sin(lat[1:])), rtol=1e-12)
    # cube: each face holds 4 pi / 6; a corner texel by numerical integration over the face plane
    n = 4
    sa = wenv.Environment(np.ones((3 * n, 4 * n, 3), np.float32), projection="cube_cross").solid_angles()
    for col, row, *_ in HCROSS.values():
        assert sa[row * n:(row + 1) * n, col * n:(col + 1) * n].sum() == pytest.approx(FOUR_PI / 6, rel=1e-12)
    assert sa[0, 0] == 0 and sa[0, 3 * n] == 0
    m = 2000
    s = -1 + (np.arange(m) + 0.5) / m * (2 / n)
    S, T = np.meshgrid(s, s)
    numeric = np.sum((1 + S**2 + T**2) ** -1.5) * (2 / n / m) ** 2
    assert sa[n, n] == pytest.approx(numeric, rel=1e-6)
    # mirror ball: 4 x (area of pixel inside the unit disk), checked on rim pixels by fine subdivision
    h = w = 8
    sa = wenv.Environment(np.ones((h, w, 3), np.float32), projection="mirror_ball").solid_angles()
    m = 4000
    for row, col in [(0, 2), (1, 1), (0, 3), (2, 0), (3, 3)]:
        x = -1 + (col + (np.arange(m) + 0.5) / m) * 2 / w
        z = 1 - (row + (np.arange(m) + 0.5) / m) * 2 / h
        X, Z = np.meshgrid(x, z)
        numeric = 4 * np.count_nonzero(X**2 + Z**2 <= 1) * (2 / w / m) * (2 / h / m)
        assert sa[row, col] == pytest.approx(numeric, rel=2e-3, abs=1e-6)
    assert sa[0, 0] == 0.0  # corner pixel is outside the disk


@pytest.mark.parametrize("projection,shape", [("equirect", (32, 64)), ("mirror_ball", (40, 40)),
                                              ("cube_cross", (48, 64)), ("cube_cross", (64, 48))])
def test_samples_match_lookup_and_solid_angles(projection, shape):
    rng = np.random.default_rng(5)
    img = rng.uniform(0.1, 2.0, shape + (3,)).astype(np.float32)
    img[3, 5] = 0.0  # black pixels are kept: their solid angle normalises filtering
    strength, rotation = 1.7, 0.9
    env = wenv.Environment(img, projection=projection, rotation=rotation, strength=strength)
    dirs, flux = env.samples()
    sa = env.solid_angles()
    keep = sa > 0
    assert dirs.shape == flux.shape == (np.count_nonzero(keep), 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(flux, img[keep] * strength * sa[keep][:, None], rtol=1e-5)
    # a pixel centre's world direction (rotation applied) reads that pixel back
    inner = keep.copy()
    if projection == "mirror_ball":  # pixels cut by the rim have their point moved onto the disk
        x = (2.0 * np.arange(shape[1]) + 1.0 - shape[1]) / shape[1]
        z = (shape[0] - 2.0 * np.arange(shape[0]) - 1.0) / shape[0]
        inner &= (x[None, :] ** 2 + z[:, None] ** 2) < 0.8
    got = env.lookup(dirs)[inner[keep]]
    np.testing.assert_allclose(got, img[inner] * strength, rtol=2e-3, atol=1e-4)


def test_samples_integrate_constant_environment():
    for projection, shape in [("equirect", (64, 128)), ("mirror_ball", (101, 101)), ("cube_cross", (30, 40))]:
        env = wenv.Environment(np.full(shape + (3,), 0.5, np.float32), projection=projection, strength=2.0)
        dirs, flux = env.samples()
        assert flux.astype(np.float64).sum(axis=0) == pytest.approx([FOUR_PI] * 3, rel=1e-6)
        # the first moment of a constant environment vanishes
        assert np.abs((dirs * flux[:, :1]).sum(axis=0)).max() < 1e-3


# ------------------------------------------------------------------------------------------------
# lookup details and the Python type


def test_lookup_edge_cases():
    rng = np.random.default_rng(6)
    for projection, shape in [("equirect", (16, 32)), ("mirror_ball", (16, 16)), ("cube_cross", (12, 16))]:
        env = wenv.Environment(rng.uniform(0, 1, shape + (3,)).astype(np.float32), projection=projection)
        special = [[0, 0, 1], [0, 0, -1], [-1, 0, 0], [-1, 1e-12, 0], [-1, -1e-12, 0], [0, 1, 0], [1, 1, 1],
                   [1, 1, 0], [1e-30, 0, 1], [-1, -1e-30, -1e-30]]
        out = env.lookup(f32(special))
        assert out.shape == (len(special), 3) and np.all(np.isfinite(out)), projection
        d = random_dirs(5000, 7)
        out = env.lookup(f32(d))
        assert np.all(np.isfinite(out)) and out.min() >= 0 and out.max() <= 1 + 1e-6
        # directions need not be unit; a single (3,) vector gives a (3,) result
        np.testing.assert_allclose(env.lookup(f32(d[:50] * 7.5)), out[:50], rtol=1e-5)
        single = env.lookup(f32(d[0]))
        assert single.shape == (3,)
        np.testing.assert_allclose(single, out[0], rtol=1e-6)
    # large batches (GIL released, OpenMP) equal small ones
    env = wenv.Environment(rng.uniform(0, 1, (64, 128, 3)).astype(np.float32))
    d = f32(random_dirs(100_000, 8))
    big = env.lookup(d)
    np.testing.assert_array_equal(big[:500], env.lookup(d[:500]))
    assert env.lookup(np.zeros((0, 3), np.float32)).shape == (0, 3)


def test_equirect_seam_and_poles_continuous():
    rng = np.random.default_rng(9)
    env = wenv.Environment(rng.uniform(0, 1, (16, 32, 3)).astype(np.float32))
    eps = 1e-6
    a = env.lookup(f32([-1, eps, 0]))
    b = env.lookup(f32([-1, -eps, 0]))
    np.testing.assert_allclose(a, b, atol=1e-4)
    # near a pole every azimuth reads the (clamped) top row blend, no NaN
    ring = np.stack([np.cos(np.linspace(0, 6, 50)) * 1e-7, np.sin(np.linspace(0, 6, 50)) * 1e-7, np.ones(50)], -1)
    assert np.all(np.isfinite(env.lookup(f32(ring))))


def test_environment_type():
    rng = np.random.default_rng(10)
    img = rng.uniform(-0.5, 2, (6, 12, 4)).astype(np.float32)
    env = wenv.Environment(img, "equirect", 0.25, 3.0)
    assert (env.width, env.height, env.projection, env.rotation, env.strength) == (12, 6, "equirect", 0.25, 3.0)
    px = env.pixels
    assert px.shape == (6, 12, 3) and px.dtype == np.float32
    np.testing.assert_array_equal(px, np.maximum(img[..., :3], 0))  # alpha ignored, negatives clamped
    px[:] = 99  # a copy
    assert env.pixels.max() < 3
    for attr in ["width", "height", "projection", "rotation", "strength", "pixels"]:
        with pytest.raises(AttributeError):
            setattr(env, attr, 1)
    other = env.with_transform(rotation=1.0)
    assert (other.rotation, other.strength) == (1.0, 3.0) and (env.rotation, env.strength) == (0.25, 3.0)
    other = env.with_transform(strength=0.5)
    assert (other.rotation, other.strength) == (0.25, 0.5)
    np.testing.assert_allclose(other.lookup(f32([1, 2, 3])), env.lookup(f32([1, 2, 3])) / 6, rtol=1e-6)
    assert isinstance(env.with_transform(), wenv.Environment)
    assert "Environment(12x6" in repr(env)
    # the source buffer may change afterwards
    img[:] = 0
    assert env.pixels.max() > 0


def test_bad_arrays():
    ok = np.ones((4, 8, 3), np.float32)
    with pytest.raises(TypeError, match="float32"):
        wenv.Environment(ok.astype(np.float64))
    with pytest.raises(TypeError, match="pixels"):
        wenv.Environment([[[1.0, 1.0, 1.0]]])
    with pytest.raises(ValueError, match="shape"):
        wenv.Environment(np.ones((4, 8), np.float32))
    with pytest.raises(ValueError, match="shape"):
        wenv.Environment(np.ones((4, 8, 2), np.float32))
    with pytest.raises(ValueError, match="contiguous"):
        wenv.Environment(np.ones((4, 16, 3), np.float32)[:, ::2])
    with pytest.raises(ValueError, match="empty"):
        wenv.Environment(np.ones((0, 8, 3), np.float32))
    with pytest.raises(ValueError, match="empty"):
        wenv.Environment(np.ones((4, 0, 3), np.float32))
    for bad in [np.nan, np.inf, -np.inf]:
        img = ok.copy()
        img[2, 5, 1] = bad
        with pytest.raises(ValueError, match=r"pixels.*row 2, column 5, channel 1.*not finite"):
            wenv.Environment(img)
    with pytest.raises(ValueError, match="'equirect', 'mirror_ball', 'cube_cross'"):
        wenv.Environment(ok, projection="cubemap")
    with pytest.raises(TypeError, match="projection"):
        wenv.Environment(ok, projection=2)
    for bad in [np.nan, np.inf]:
        with pytest.raises(ValueError, match="rotation"):
            wenv.Environment(ok, rotation=bad)
        with pytest.raises(ValueError, match="strength"):
            wenv.Environment(ok, strength=bad)
    with pytest.raises(ValueError, match="strength"):
        wenv.Environment(ok, strength=-1.0)
    with pytest.raises(TypeError, match="strength"):
        wenv.Environment(ok, strength="2")
    with pytest.raises(ValueError, match="4:3"):
        wenv.Environment(np.ones((30, 30, 3), np.float32), projection="cube_cross")
    with pytest.raises(ValueError, match="4:3"):
        wenv.Environment(np.ones((30, 41, 3), np.float32), projection="cube_cross")
    env = wenv.Environment(ok)
    with pytest.raises(ValueError, match="strength"):
        env.with_transform(strength=-2)
    with pytest.raises(ValueError, match="rotation"):
        env.with_transform(rotation=float("nan"))
    with pytest.raises(TypeError, match="dirs"):
        env.lookup(np.ones((3, 3)))
    with pytest.raises(ValueError, match="dirs"):
        env.lookup(np.ones((3, 4), np.float32))
    with pytest.raises(ValueError, match=r"dirs\[1\].*zero"):
        env.lookup(f32([[1, 0, 0], [0, 0, 0]]))
    with pytest.raises(ValueError, match="dirs"):
        env.lookup(f32([[1, 0, np.nan]]))


# ------------------------------------------------------------------------------------------------
# files


def test_exr_variants(tmp_path):
    rng = np.random.default_rng(11)
    img = rng.uniform(0, 40, (21, 37, 4)).astype(np.float32)
    img16 = img.astype(np.float16).astype(np.float32)
    cases = [
        ("scan_float_rgb.exr", dict(pixel_type="float", channels="RGB"), img[..., :3]),
        ("scan_half_rgba.exr", dict(pixel_type="half", channels="RGBA"), img16[..., :3]),
        ("tiled_float.exr", dict(pixel_type="float", channels="RGBA", tile=(16, 8)), img[..., :3]),
        ("tiled_half.exr", dict(pixel_type="half", channels="RGB", tile=(5, 7)), img16[..., :3]),
        ("offset_window.exr", dict(pixel_type="float", channels="RGB", origin=(-7, 12)), img[..., :3]),
        ("offset_tiled.exr", dict(pixel_type="half", channels="RGB", tile=(8, 8), origin=(3, -4)), img16[..., :3]),
    ]
    for name, kw, expect in cases:
        path = tmp_path / name
        write_exr(path, img[..., :len(kw["channels"])], **kw)
        env = wenv.load_environment(path)
        assert (env.height, env.width) == (21, 37), name
        np.testing.assert_array_equal(env.pixels, expect, err_msg=name)
    # luminance-only files read as grey
    write_exr(tmp_path / "y.exr", img[..., :1], channels="Y")
    np.testing.assert_array_equal(wenv.load_environment(str(tmp_path / "y.exr")).pixels, np.repeat(img[..., :1], 3, -1))
    # projection, rotation and strength pass through
    env = wenv.load_environment(os.fsencode(tmp_path / "scan_float_rgb.exr"), "equirect", 0.5, 2.0)
    assert (env.rotation, env.strength) == (0.5, 2.0)
    # a cube cross from a file, and one with the wrong aspect
    write_exr(tmp_path / "cross.exr", np.ones((12, 16, 3), np.float32))
    assert wenv.load_environment(tmp_path / "cross.exr", projection="cube_cross").projection == "cube_cross"
    with pytest.raises(ValueError, match="scan_float_rgb.exr.*4:3"):
        wenv.load_environment(tmp_path / "scan_float_rgb.exr", projection="cube_cross")
    # non-finite pixels in a file
    bad = img[..., :3].copy()
    bad[3, 4, 2] = np.inf
    write_exr(tmp_path / "inf.exr", bad)
    with pytest.raises(OSError, match="inf.exr.*not finite"):  # a fault of the file, as every other
        wenv.load_environment(tmp_path / "inf.exr")
    bad[3, 4, 2] = 1e30  # finite, but beyond what float32 shading can hold
    write_exr(tmp_path / "huge.exr", bad)
    with pytest.raises(OSError, match=r"huge.exr.*1e\+30, more than 1e\+18"):
        wenv.load_environment(tmp_path / "huge.exr")
    # no colour channels
    write_exr(tmp_path / "z.exr", img[..., :1], channels="Z")
    with pytest.raises(OSError, match="z.exr.*R, G and B"):
        wenv.load_environment(tmp_path / "z.exr")


def test_every_exr_channel_set_reads_or_is_refused(tmp_path):
    """Every set of the channels R, G, B, A, Y and Z, in half and float, scanline and tiled: with R,
    G and B the colour is read, else with Y the grey, else an OSError -- never a crash (OpenEXRCore
    3.1 wrote through a skipped channel when three half channels held Y and two of R, G, B).  Read
    in a child process, so that a crash fails this test instead of ending the run."""
    import itertools
    import subprocess
    import sys
    rng = np.random.default_rng(17)
    planes = {c: np.float32(np.float16(rng.uniform(0.1, 4.0, (9, 13)))) for c in "RGBAYZ"}
    cases = []
    for k in range(1, 7):
        for chans in itertools.combinations("RGBAYZ", k):
            for pixel_type, tile in (("half", None), ("float", None), ("half", (4, 4)), ("float", (8, 3))):
                name = f"{''.join(chans)}_{pixel_type}_{'tiled' if tile else 'scan'}.exr"
                write_exr(tmp_path / name, np.stack([planes[c] for c in chans], -1), pixel_type, "".join(chans), tile)
                if {"R", "G", "B"} <= set(chans):
                    want = np.stack([planes[c] for c in "RGB"], -1)
                elif "Y" in chans:
                    want = np.repeat(planes["Y"][..., None], 3, -1)
                else:
                    want = None
                cases.append((name, want))
    script = (
        f"import sys\nsys.path.insert(0, {os.path.dirname(wenv.__file__)!r})\nimport numpy as np, wenv\n"
        "for name in sys.argv[2:]:\n"
        "    try:\n"
        "        np.save(sys.argv[1] + '/' + name + '.npy', wenv.load_environment(sys.argv[1] + '/' + name).pixels)\n"
        "    except OSError as e:\n"
        "        open(sys.argv[1] + '/' + name + '.err', 'w').write(str(e))\n")
    run = subprocess.run([sys.executable, "-c", script, str(tmp_path)] + [n for n, _ in cases], capture_output=True)
    assert run.returncode == 0, run.stderr.decode()[-2000:]
    assert len(cases) == 63 * 4
    for name, want in cases:
        if want is None:
            assert "R, G and B (or Y)" in (tmp_path / (name + ".err")).read_text(), name
        else:
            np.testing.assert_array_equal(np.load(tmp_path / (name + ".npy")), want, err_msg=name)


def test_hdr_files(tmp_path):
    rng = np.random.default_rng(12)
    h, w = 9, 40
    rgb = rng.uniform(0, 5, (h, w, 3)) * np.exp(rng.uniform(-8, 8, (h, w, 1)))
    rgb[2, 10:30] = 1.25  # runs for the RLE coder
    rgb[4, :] = 0.0
    q = rgbe_encode(rgb)
    expect = rgbe_decode(q)
    big = rgb.max(-1) > 1e-30
    np.testing.assert_allclose(expect.max(-1)[big], rgb.max(-1)[big], rtol=1e-2)  # the helper itself
    for rle in [True, False]:
        path = tmp_path / ("rle.hdr" if rle else "flat.hdr")
        write_hdr(path, q, rle=rle)
        env = wenv.load_environment(path)
        assert (env.height, env.width) == (h, w)
        np.testing.assert_array_equal(env.pixels, expect)
    # narrow images (< 8 pixels) are always flat; "#?RGBE" header, CRLF-free variables
    write_hdr(tmp_path / "narrow.hdr", q[:, :5], rle=False, header=b"#?RGBE\n# comment\nFORMAT=32-bit_rle_rgbe\n\n")
    np.testing.assert_array_equal(wenv.load_environment(tmp_path / "narrow.hdr").pixels, expect[:, :5])
    # old-style run: (1, 1, 1, n) repeats the previous pixel n times
    px = bytes([100, 50, 25, 129])
    body = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 10\n" + px + bytes([1, 1, 1, 9])
    (tmp_path / "oldrle.hdr").write_bytes(body)
    np.testing.assert_array_equal(wenv.load_environment(tmp_path / "oldrle.hdr").pixels,
                                  np.repeat(rgbe_decode(np.frombuffer(px, np.uint8).reshape(1, 1, 4)), 10, axis=1))
    # unsupported variants are rejected by name
    write_hdr(tmp_path / "xyze.hdr", q, header=b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n")
    with pytest.raises(OSError, match="xyze.hdr.*32-bit_rle_rgbe"):
        wenv.load_environment(tmp_path / "xyze.hdr")
    # bytes that are not UTF-8, in a header or a file name, are an OSError that shows them escaped
    latin = os.fsencode(tmp_path) + b"/latin\xe9.hdr"
    write_hdr(latin, q, header=b"#?RADIANCE\nFORMAT=\xff\xfe\n\n")
    with pytest.raises(OSError, match=r"latin\\xe9\.hdr.*32-bit_rle_rgbe"):
        wenv.load_environment(latin)
    write_hdr(tmp_path / "flipy.hdr", q, res=b"+Y %d +X %d\n" % (h, w))
    with pytest.raises(OSError, match="flipy.hdr.*orientation"):
        wenv.load_environment(tmp_path / "flipy.hdr")
    write_hdr(tmp_path / "xfirst.hdr", q, res=b"+X %d -Y %d\n" % (w, h))
    with pytest.raises(OSError, match="xfirst.hdr.*orientation"):
        wenv.load_environment(tmp_path / "xfirst.hdr")
    # truncations and garbage after a valid header
    data = (tmp_path / "rle.hdr").read_bytes()
    head = data.index(b"-Y")
    for n in [2, 10, head, head + 5, head + 20, len(data) // 2, len(data) - 1]:
        (tmp_path / "cut.hdr").write_bytes(data[:n])
        with pytest.raises(OSError, match="cut.hdr"):
            wenv.load_environment(tmp_path / "cut.hdr")
    rng = np.random.default_rng(13)
    resline = data.index(b"\n", head) + 1
    for i in range(20):
        junk = rng.integers(0, 256, rng.integers(0, w * h * 4 - 1), dtype=np.uint8).tobytes()
        if i % 2:  # a plausible RLE scanline start with a broken body
            junk = bytes([2, 2, 0, w]) + junk
        (tmp_path / "junk.hdr").write_bytes(data[:resline] + junk)
        with pytest.raises(OSError, match="junk.hdr"):
            wenv.load_environment(tmp_path / "junk.hdr")
    bad_width = bytearray(data)
    bad_width[resline + 3] = w + 1  # RLE scanline claims another width
    (tmp_path / "badw.hdr").write_bytes(bytes(bad_width))
    with pytest.raises(OSError, match="badw.hdr.*wrong width"):
        wenv.load_environment(tmp_path / "badw.hdr")


def test_file_errors(tmp_path):
    missing = tmp_path / "nope.exr"
    with pytest.raises(OSError, match="nope.exr"):
        wenv.load_environment(missing)
    with pytest.raises(OSError, match="directory"):
        wenv.load_environment(tmp_path)
    os.mkfifo(tmp_path / "fifo.hdr")  # must not block waiting for a writer
    with pytest.raises(OSError, match="fifo.hdr.*not a regular file"):
        wenv.load_environment(tmp_path / "fifo.hdr")
    (tmp_path / "empty.hdr").write_bytes(b"")
    with pytest.raises(OSError, match="empty.hdr"):
        wenv.load_environment(tmp_path / "empty.hdr")
    (tmp_path / "text.exr").write_bytes(b"hello, this is not an image\n" * 10)
    with pytest.raises(OSError, match="text.exr.*neither OpenEXR nor Radiance"):
        wenv.load_environment(tmp_path / "text.exr")
    with pytest.raises(TypeError, match="path"):
        wenv.load_environment(3)
    with pytest.raises(ValueError, match="projection"):
        wenv.load_environment(hdri_path("forest"), projection="sphere")
    with pytest.raises(ValueError, match="strength"):
        wenv.load_environment(hdri_path("forest"), strength=-1)


def test_corrupt_exr(tmp_path):
    src = open(hdri_path("forest"), "rb").read()
    head = exr_header_length(src)
    rng = np.random.default_rng(14)
    path = tmp_path / "bad.exr"
    for n in [4, 10, 100, head - 1, head, head + 9, head + 200, len(src) // 3, len(src) - 500, len(src) - 1]:
        path.write_bytes(src[:n])
        with pytest.raises(OSError, match="bad.exr"):
            wenv.load_environment(path)
    for i in range(6):  # random bytes after a valid header (and after a valid offset table)
        keep = head if i < 3 else head + 8 * 16
        path.write_bytes(src[:keep] + rng.integers(0, 256, len(src) - keep, dtype=np.uint8).tobytes())
        with pytest.raises(OSError, match="bad.exr"):
            wenv.load_environment(path)
    # our own uncompressed files: truncated and scrambled
    write_exr(tmp_path / "ok.exr", rng.uniform(0, 1, (16, 16, 3)), tile=(8, 8))
    data = (tmp_path / "ok.exr").read_bytes()
    head = exr_header_length(data)
    for n in [head + 3, head + 40, len(data) - 1]:
        path.write_bytes(data[:n])
        with pytest.raises(OSError, match="bad.exr"):
            wenv.load_environment(path)
    path.write_bytes(data[:head] + rng.integers(0, 256, len(data) - head, dtype=np.uint8).tobytes())
    with pytest.raises(OSError, match="bad.exr"):
        wenv.load_environment(path)


def load_under_allocation_limit(path):
    """What wenv.load_environment(path) raises, as 'TypeName message', in a child process whose
    allocations are limited to 3 GB."""
    import subprocess
    import sys

    env = dict(os.environ)
    # AddressSanitizer (scripts/sanitize_tests.sh) reserves terabytes of address space, so there
    # its allocator's own limit stands in for the address-space limit
    asan = "libasan" in env.get("LD_PRELOAD", "")
    env["ASAN_OPTIONS"] = env.get("ASAN_OPTIONS", "") + ":allocator_may_return_null=1:max_allocation_size_mb=3072"
    code = (f"import resource, sys\nsys.path.insert(0, {os.path.dirname(wenv.__file__)!r})\n"
            + ("" if asan else "resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))\n")
            + f"import wenv\ntry:\n    wenv.load_environment({str(path)!r})\n"
            + "except Exception as e:\n    print(type(e).__name__, e)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_exr_window_beyond_the_file_is_refused_before_allocating(tmp_path):
    """A header claiming 327681 x 1793 pixels over a few hundred bytes (found by tests/fuzz) is a
    corrupt file, found before the 7 GB image is allocated: under a 3 GB limit on allocations that
    allocation would fail as a MemoryError."""
    write_exr(tmp_path / "ok.exr", np.ones((6, 8, 3), np.float32))
    data = (tmp_path / "ok.exr").read_bytes()
    box = struct.pack("<iiii", 0, 0, 7, 5)
    window = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    assert data[window:window + 16] == box
    (tmp_path / "huge.exr").write_bytes(data[:window] + struct.pack("<iiii", 0, 0, 327680, 1792) + data[window + 16:])
    out = load_under_allocation_limit(tmp_path / "huge.exr")
    assert out.startswith("OSError cannot read OpenEXR file") and "huge.exr" in out, out


def exr_with_chunks(header, window, compression, lines_per_chunk, payload):
    """A scanline OpenEXR file: `header` (a file of write_exr's whose header is reused) with its data
    window and compression replaced, and one chunk of `payload` bytes per `lines_per_chunk` rows."""
    head = header[:exr_header_length(header)]
    w = head.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    head = head[:w] + struct.pack("<iiii", 0, 0, window[0] - 1, window[1] - 1) + head[w + 16:]
    c = head.index(b"compression\0compression\0") + len(b"compression\0compression\0") + 4
    head = head[:c] + bytes([compression]) + head[c + 1:]
    n = -(-window[1] // lines_per_chunk)
    chunks = [struct.pack("<ii", k * lines_per_chunk, len(payload)) + payload for k in range(n)]
    offsets = np.cumsum([len(head) + 8 * n] + [len(ch) for ch in chunks[:-1]])
    return head + b"".join(struct.pack("<Q", int(o)) for o in offsets) + b"".join(chunks)


def test_exr_chunks_shorter_than_their_pixels_are_refused(tmp_path):
    """Uncompressed chunks of 96 bytes under a window 800 pixels wide (found by tests/fuzz): an
    OSError saying so; OpenEXRCore decodes such a chunk to nothing, and the file read as black."""
    write_exr(tmp_path / "ok.exr", np.ones((6, 8, 3), np.float32))
    data = (tmp_path / "ok.exr").read_bytes()
    np.testing.assert_array_equal(wenv.load_environment(tmp_path / "ok.exr").pixels, 1.0)
    (tmp_path / "short.exr").write_bytes(exr_with_chunks(data, (800, 6), 0, 1, data[-96:]))
    with pytest.raises(OSError, match=r"short.exr.*holds 96 bytes for 9600 bytes"):
        wenv.load_environment(tmp_path / "short.exr")


def test_dwa_window_beyond_the_file_is_refused_before_allocating(tmp_path):
    """A DWAA header claiming 32768 x 32768 pixels over 1024 chunks of 16 bytes: OpenEXR's C++ library
    reads it in bands, so the corrupt first chunk is an OSError, not a 20 GB allocation."""
    write_exr(tmp_path / "ok.exr", np.ones((4, 8, 3), np.float32), pixel_type="half")
    data = (tmp_path / "ok.exr").read_bytes()
    (tmp_path / "huge_dwa.exr").write_bytes(exr_with_chunks(data, (32768, 32768), 8, 32, bytes(range(16))))
    out = load_under_allocation_limit(tmp_path / "huge_dwa.exr")
    assert out.startswith("OSError cannot read OpenEXR file") and "huge_dwa.exr" in out, out


def test_hdr_size_beyond_the_file_is_refused_before_allocating(tmp_path):
    """The same for a Radiance header claiming 32768 x 32768 pixels (12 GB) over 8 pixels."""
    rgbe = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 32768 +X 32768\n" + bytes([128, 128, 128, 129]) * 8
    (tmp_path / "huge.hdr").write_bytes(rgbe)
    out = load_under_allocation_limit(tmp_path / "huge.hdr")
    assert out.startswith("OSError cannot read Radiance HDR file") and "huge.hdr" in out and "truncated" in out, out


def test_dwa_file_with_header_faults_is_refused(tmp_path):
    """OpenEXRCore steps over an attribute of impossible size; OpenEXR's C++ library, which decodes
    DWAA/DWAB, would allocate what the size claims (1.5 GB here, seconds of work; found by
    tests/fuzz).  Such a file is refused with OpenEXRCore's diagnosis."""
    write_exr(tmp_path / "ok.exr", np.ones((4, 8, 3), np.float32), pixel_type="half")
    data = (tmp_path / "ok.exr").read_bytes()
    c = data.index(b"compression\0compression\0") + len(b"compression\0compression\0") + 4
    data = data[:c] + b"\x08" + data[c + 1:]  # DWAA: the C++ library's part (the payload is not DWAA)
    head = exr_header_length(data)
    bad = b"note\0string\0" + struct.pack("<i", 1500000000)  # no value follows
    (offset,) = struct.unpack("<Q", data[head:head + 8])  # one chunk of 32 lines for DWAA
    faulty = data[:head - 1] + bad + b"\0" + struct.pack("<Q", offset + len(bad)) + data[head + 8:]
    (tmp_path / "dwa.exr").write_bytes(data)
    with pytest.raises(OSError, match="dwa.exr.*DWA"):  # the C++ library reached, and refusing the payload
        wenv.load_environment(tmp_path / "dwa.exr")
    (tmp_path / "faulty.exr").write_bytes(faulty)
    with pytest.raises(OSError, match="faulty.exr.*'note'.*[Ii]nvalid size 1500000000"):
        wenv.load_environment(tmp_path / "faulty.exr")


def test_bundled_hdris_load():
    for name in HDRI_NAMES:
        env = wenv.load_environment(hdri_path(name))
        assert (env.width, env.height, env.projection) == (1024, 512, "equirect"), name
        px = env.pixels
        assert np.all(np.isfinite(px)) and px.min() >= 0 and px.max() > 1.0, name
        assert env.solid_angles().sum() == pytest.approx(FOUR_PI, rel=1e-9)
    sun = wenv.load_environment(hdri_path("sunrise")).pixels.max()
    assert 10_000 < sun < 65_504


# ------------------------------------------------------------------------------------------------
# against Blender


@pytest.fixture(scope="module")
def bpy():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy


def bpy_pixels(img):
    """RGBA float pixels of a bpy image as (H, W, 4), row 0 the top."""
    w, h = img.size
    a = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(a)
    return a.reshape(h, w, 4)[::-1]


def test_bundled_hdris_match_blender(bpy):
    for name in ["forest", "sunrise", "night"]:
        env = wenv.load_environment(hdri_path(name))
        img = bpy.data.images.load(hdri_path(name))
        ref = bpy_pixels(img)[..., :3]
        bpy.data.images.remove(img)
        np.testing.assert_array_equal(env.pixels, np.maximum(ref, 0), err_msg=name)  # wenv clamps negatives
        r, c = np.unravel_index(np.argmax(ref[..., 0]), ref.shape[:2])
        assert env.pixels[r, c, 0] == ref[r, c, 0] > 1000 or name == "forest"


@pytest.mark.parametrize("codec,depth", [("ZIP", "32"), ("PIZ", "16"), ("RLE", "16"), ("ZIPS", "32"),
                                         ("PXR24", "32"), ("B44", "16"), ("DWAA", "16"), ("NONE", "16")])
def test_exr_codecs_match_blender(bpy, tmp_path, codec, depth):
    rng = np.random.default_rng(15)
    h, w = 24, 40
    src = np.concatenate([rng.uniform(0, 30, (h, w, 3)), np.ones((h, w, 1))], -1).astype(np.float32)
    img = bpy.data.images.new("codec", w, h, float_buffer=True, alpha=True)
    img.pixels.foreach_set(src[::-1].ravel())
    scene = bpy.context.scene
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGBA"
    settings.color_depth = depth
    settings.exr_codec = codec
    path = str(tmp_path / f"{codec}.exr")
    img.save_render(path, scene=scene)
    bpy.data.images.remove(img)
    back = bpy.data.images.load(path)
    ref = bpy_pixels(back)[..., :3]
    bpy.data.images.remove(back)
    env = wenv.load_environment(path)
    np.testing.assert_array_equal(env.pixels, np.maximum(ref, 0))
    if codec in ("ZIP", "PIZ", "RLE", "ZIPS", "NONE"):  # lossless
        expect = src[..., :3] if depth == "32" else src[..., :3].astype(np.float16).astype(np.float32)
        np.testing.assert_array_equal(env.pixels, expect)
    # corrupt payloads through OpenEXRCore's decompressors: an exception, never a crash
    data = open(path, "rb").read()
    head = exr_header_length(data)
    for i in range(4):
        junk = bytearray(data)
        start = head + 8 * 64 if len(data) > head + 8 * 64 + 16 else head
        for j in rng.integers(start, len(data), 40):
            junk[int(j)] = int(rng.integers(0, 256))
        bad = tmp_path / "junk.exr"
        bad.write_bytes(bytes(junk))
        try:
            wenv.load_environment(bad)
        except (OSError, ValueError) as e:
            assert "junk.exr" in str(e)


def test_hdr_matches_blender(bpy, tmp_path):
    rng = np.random.default_rng(16)
    rgb = rng.uniform(0, 3, (10, 24, 3)) * np.exp(rng.uniform(-3, 3, (10, 24, 1)))
    write_hdr(tmp_path / "b.hdr", rgbe_encode(rgb))
    img = bpy.data.images.load(str(tmp_path / "b.hdr"))
    ref = bpy_pixels(img)[..., :3]
    bpy.data.images.remove(img)
    np.testing.assert_array_equal(wenv.load_environment(tmp_path / "b.hdr").pixels, ref)


def _setup_cycles(bpy, res):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1  # Cycles' first sample sits at the pixel centre
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 0.01
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 2
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.exr_codec = "NONE"
    return scene


def _world(bpy, scene, image, projection, rotation, strength):
    world = bpy.data.worlds.new("wenv-test")
    scene.world = world
    world.cycles.sampling_method = "NONE"  # no importance map: the render takes milliseconds
    nt = world.node_tree
    nt.nodes.clear()
    coords = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation)
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = image
    tex.projection = projection
    tex.interpolation = "Linear"
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = strength
    out = nt.nodes.new("ShaderNodeOutputWorld")
    nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])


def _render_views(bpy, scene, tmp_path, res, fov, views):
    """Renders the world with a perspective camera looking along each view; returns (dirs, colours)."""
    from mathutils import Vector

    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "PERSP"
    cam_data.sensor_fit = "AUTO"
    cam_data.lens_unit = "FOV"
    cam_data.angle = fov
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    t = (2.0 * (np.arange(res) + 0.5) / res - 1.0) * math.tan(fov / 2)
    X, Y = np.meshgrid(t, t[::-1])  # image row 0 is the top
    local = np.stack([X, Y, -np.ones_like(X)], -1)  # a camera looks along its -Z, +Y up
    dirs, colours = [], []
    for k, view in enumerate(views):
        cam.matrix_world = Vector(view).to_track_quat("-Z", "Y").to_matrix().to_4x4()
        bpy.context.view_layer.update()
        path = str(tmp_path / f"render{k}.exr")
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(path)
        colours.append(bpy_pixels(img)[..., :3].reshape(-1, 3))
        bpy.data.images.remove(img)
        m = np.array(cam.matrix_world)[:3, :3]
        dirs.append(unit(local @ m.T).reshape(-1, 3))
    return np.concatenate(dirs), np.concatenate(colours)


VIEWS = [(1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (1, 1, 0.5), (-1, 0.5, -0.7)]


def _test_image(bpy, pixels_top_first):
    """A float bpy image with these pixels (no colour conversion); returns it and the wenv pixels."""
    h, w, _ = pixels_top_first.shape
    img = bpy.data.images.new("env", w, h, float_buffer=True, alpha=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.concatenate([pixels_top_first, np.ones((h, w, 1))], -1).astype(np.float32)
    img.pixels.foreach_set(rgba[::-1].ravel())  # Blender stores the bottom row first
    return img, f32(bpy_pixels(img))  # what Blender holds, flipped back to row 0 the top


def _assert_matches_cycles(env, dirs, colours, keep):
    expect = env.lookup(f32(dirs))
    err = np.abs(colours - expect)[keep]
    assert keep.sum() > 200
    assert err.max() < 2e-3, f"max error {err.max():.4g} vs Cycles"


def test_orientation_against_cycles(bpy, tmp_path):
    res, fov = 16, math.radians(90)
    # equirect: smooth, periodic in u, no mirror or rotation symmetry
    h, w = 32, 64
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    U, V = np.meshgrid(u, v)
    pixels = np.stack([0.5 + 0.3 * np.sin(2 * np.pi * U) + 0.1 * np.cos(4 * np.pi * U), 0.3 + 0.5 * V,
                       0.4 + 0.2 * np.cos(2 * np.pi * U) * np.sin(np.pi * V)], -1)
    for rotation, strength in [(0.0, 1.0), (0.7, 2.5), (-2.0, 0.8)]:
        scene = _setup_cycles(bpy, res)
        image, px = _test_image(bpy, pixels)
        _world(bpy, scene, image, "EQUIRECTANGULAR", rotation, strength)
        dirs, colours = _render_views(bpy, scene, tmp_path, res, fov, VIEWS)
        env = wenv.Environment(px, projection="equirect", rotation=rotation, strength=strength)
        # Cycles wraps vertically at the poles where wenv clamps: skip the outermost texel rows
        keep = np.abs(dirs[:, 2]) < math.cos(1.5 * math.pi / h)
        _assert_matches_cycles(env, dirs, colours, keep)
        # the test can fail: a mirrored image or a quarter-turn error are far off
        for wrong in [wenv.Environment(px[:, ::-1].copy(), rotation=rotation, strength=strength),
                      wenv.Environment(px[::-1].copy(), rotation=rotation, strength=strength),
                      env.with_transform(rotation=rotation + math.pi / 2),
                      env.with_transform(rotation=-rotation + 0.3)]:
            assert np.abs(colours - wrong.lookup(f32(dirs)))[keep].max() > 0.05
    # mirror ball: a square image, smooth over the disk, with a rotation
    n = 48
    x = (2.0 * np.arange(n) + 1.0 - n) / n
    X, Z = np.meshgrid(x, x[::-1])
    pixels = np.stack([0.5 + 0.3 * X + 0.1 * Z * Z, 0.4 + 0.35 * Z, 0.5 + 0.2 * X * Z], -1)
    scene = _setup_cycles(bpy, res)
    image, px = _test_image(bpy, pixels)
    rotation, strength = 0.6, 1.5
    _world(bpy, scene, image, "MIRROR_BALL", rotation, strength)
    dirs, colours = _render_views(bpy, scene, tmp_path, res, fov, VIEWS)
    env = wenv.Environment(px, projection="mirror_ball", rotation=rotation, strength=strength)
    # away from the rim (image direction near +Y), where texels stretch without bound
    keep = (dirs @ rot_z(rotation).T)[:, 1] < 0.5
    _assert_matches_cycles(env, dirs, colours, keep)
    for wrong in [wenv.Environment(px[:, ::-1].copy(), "mirror_ball", rotation, strength),
                  wenv.Environment(px[::-1].copy(), "mirror_ball", rotation, strength),
                  env.with_transform(rotation=rotation + math.pi / 2), env.with_transform(rotation=-rotation)]:
        assert np.abs(colours - wrong.lookup(f32(dirs)))[keep].max() > 0.05


def test_a_turned_copy_shares_the_image_and_outlives_its_original():
    """with_transform shares the (never changed) image instead of copying it; whichever of the
    environments goes first, the others keep the image and read it as before."""
    img = np.random.default_rng(2).random((16, 32, 3)).astype(np.float32)
    env = wenv.Environment(img, rotation=0.2)
    turned = env.with_transform(rotation=1.1, strength=2.5)
    again = turned.with_transform(rotation=0.0)
    d = np.float32([[0.3, -0.5, 0.81], [0.0, 0.0, -1.0]])
    expected = env.with_transform(rotation=1.1, strength=2.5).lookup(d)
    del env
    gc.collect()
    assert np.array_equal(turned.pixels, img) and np.array_equal(again.pixels, img)
    assert np.array_equal(turned.lookup(d), expected)
    assert (turned.rotation, turned.strength, again.rotation, again.strength) == (1.1, 2.5, 0.0, 2.5)
    del turned
    gc.collect()
    assert np.array_equal(again.pixels, img)
