"""The shading engine: exactness where the method is exact, agreement of its two variants,
finite output everywhere, caching, progress and bad input."""
import math
import os
import struct

import numpy as np
import pytest

import wenv
from conftest import WAVELET_BASE, hdri_path, random_pairs, unit

SMALL = {**WAVELET_BASE, "global": 16, "local": 8, "normals": 8, "views": 4, "coefficients": 0}


def gradient_env(h=32, w=64):
    """A smooth, coloured environment with a bright spot, so every direction differs."""
    rows, cols = np.mgrid[0:h, 0:w]
    img = np.empty((h, w, 3), np.float32)
    img[..., 0] = 0.5 + 0.5 * np.cos(2 * np.pi * cols / w)
    img[..., 1] = rows / h
    img[..., 2] = 0.2
    img[h // 4, w // 3] = (40.0, 30.0, 20.0)
    return wenv.Environment(img)


@pytest.fixture(scope="module")
def cook():
    return wenv.CookTorrance(diffuse=(0.3, 0.2, 0.1),
                             lobes=[{"specular": (1, 1, 1), "alpha": 0.3, "ior": 1.5},
                                    {"specular": (0.5, 0.6, 0.7), "alpha": 0.08, "ior": 2.0}])


@pytest.mark.parametrize("method", ["rotation", "slicing"])
@pytest.mark.parametrize("quality", ["draft", SMALL])
def test_constant_environment_lambert_is_exact(method, quality):
    env = wenv.Environment(np.full((16, 32, 3), 1.7, np.float32))
    albedo = (0.8, 0.5, 0.25)
    sh = wenv.Shader(env, wenv.Lambert(albedo), quality=quality, method=method, cache_dir=False)
    nrm, v = random_pairs(3000)
    out = sh.shade(nrm, v)
    assert np.allclose(out, 1.7 * np.array(albedo, np.float32), rtol=2e-6, atol=0)


def test_rotation_equals_slicing_without_truncation(cook):
    env = gradient_env()
    q = dict(SMALL, matrix_epsilon=0.0)
    a = wenv.Shader(env, cook, quality=q, method="rotation", cache_dir=False)
    b = wenv.Shader(env, cook, quality=q, method="slicing", cache_dir=False)
    nrm, v = random_pairs(2000, 3)
    ra, rb = a.shade(nrm, v), b.shade(nrm, v)
    assert np.max(np.abs(ra - rb)) <= 1e-4 * np.max(np.abs(rb))


def noise_env(seed=7, h=32, w=64):
    """An image without any symmetry: each slicing operator serves up to 8 normal samples through
    texel permutations, and a wrong one would read the wrong texels."""
    rng = np.random.default_rng(seed)
    return wenv.Environment(rng.lognormal(0.0, 1.0, size=(h, w, 3)).astype(np.float32))


@pytest.mark.parametrize("sizes", [(16, 8, 8), (4, 16, 6), (512, 8, 4)])
def test_slicing_shares_operators_and_equals_rotation_at_every_normal_sample(cook, sizes):
    """Rotation builds every sample's matrix from its own splat; slicing reads one operator per
    orbit of the square's symmetries.  (4, 16): local texels finer than global ones, up to 576
    taps per global texel (these sizes crashed slicing before).  (512, 8): more global texels than
    16-bit indices reach, so the kept operators hold 32-bit ones."""
    g, l, n = sizes
    env = noise_env()
    q = dict(SMALL, matrix_epsilon=0.0, light_coefficients=0, normals=n, **{"global": g, "local": l})
    a = wenv.Shader(env, cook, quality=q, method="rotation", cache_dir=False)
    b = wenv.Shader(env, cook, quality=q, method="slicing", cache_dir=False)
    # every normal sample's own direction, each seen from several views
    cells = (np.arange(n) + 0.5) / n * 2 - 1
    uu, vv = np.meshgrid(cells, cells)
    samples = np.asarray(wenv._oct_decode(np.stack([uu.ravel(), vv.ravel()], -1)), np.float32)
    nrm, v = random_pairs(4000, 5)
    nrm = np.concatenate([np.repeat(samples, 8, axis=0), nrm])
    v = np.concatenate([unit(np.repeat(samples, 8, axis=0) + 0.6 * random_pairs(8 * n * n, 6)[0]), v])
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    ra, rb = a.shade(nrm, v), b.shade(nrm, v)
    assert np.all(np.isfinite(rb)) and np.max(rb) > 0
    assert np.max(np.abs(ra - rb)) <= 1e-4 * np.max(np.abs(rb))
    assert b.stats["resampling_bytes"] > 0 and a.stats["resampling_bytes"] == 0


def test_slices_past_the_operators_budget_equal_those_kept(cook):
    """memory_budget_mb / 8 caps the operators slicing keeps; the others are made per slice and
    dropped, which changes nothing in the result."""
    env = noise_env(3)
    q = dict(SMALL, normals=16)
    kept = wenv.Shader(env, cook, quality=q, method="slicing", cache_dir=False)
    dropped = wenv.Shader(env, cook, quality=q, method="slicing", cache_dir=False, memory_budget_mb=0.05)
    nrm, v = random_pairs(3000, 8)
    ra, rb = kept.shade(nrm, v), dropped.shade(nrm, v)
    assert np.array_equal(ra, rb)
    assert dropped.stats["resampling_bytes"] <= 0.05 * 2 ** 20 / 8 < kept.stats["resampling_bytes"]
    dropped.set_environment(noise_env(4))
    kept.set_environment(noise_env(4))
    assert np.array_equal(kept.shade(nrm, v), dropped.shade(nrm, v))


def test_truncation_changes_little_and_keeps_fewer_terms(cook):
    env = gradient_env()
    full = wenv.Shader(env, cook, quality=dict(SMALL, matrix_epsilon=0.0), cache_dir=False)
    cut = wenv.Shader(env, cook, quality=dict(SMALL, matrix_epsilon=1e-3, light_coefficients=64,
                                              coefficients=32), cache_dir=False)
    assert cut.stats["rotation_nnz"] < full.stats["rotation_nnz"]
    nrm, v = random_pairs(500, 4)
    a, b = full.shade(nrm, v), cut.shade(nrm, v)
    assert np.sqrt(np.mean((a - b) ** 2)) < 0.1 * np.sqrt(np.mean(a ** 2))


def test_no_nan_at_seams_poles_and_grazing(cook):
    env = gradient_env()
    sh = wenv.Shader(env, cook, quality="draft", cache_dir=False)
    special = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (1, 1, 0), (-1, 1, 0),
               (1, -1, 0), (-1, -1, 0), (1, 1, 1), (1, 1, -1), (-1, -1, -1), (1e-7, 0, -1), (0, 1e-7, -1)]
    nrm = unit(special)
    rows_n, rows_v = [], []
    for n in nrm.astype(np.float64):
        t = np.cross(n, [0.3, 0.5, 0.8])
        t /= np.linalg.norm(t)
        for angle in (0.0, 45.0, 80.0, 89.9):
            a = math.radians(angle)
            rows_n.append(n)
            rows_v.append(math.cos(a) * n + math.sin(a) * t)
    out = sh.shade(unit(rows_n), unit(rows_v))
    assert np.all(np.isfinite(out)) and np.all(out >= 0)
    assert np.all(out.sum(axis=1) > 0)  # every one of them sees light
    # a view below the surface sees nothing
    assert np.all(sh.shade(nrm, -nrm) == 0)


def test_shade_is_continuous_across_normal_samples(cook):
    env = gradient_env()
    sh = wenv.Shader(env, cook, quality="draft", cache_dir=False)
    t = np.linspace(0, 2 * np.pi, 2001)
    nrm = unit(np.stack([np.cos(t), np.sin(t), 0.3 * np.ones_like(t)], axis=1))
    v = unit(nrm + np.array([0.0, 0.0, 0.5], np.float32))
    out = sh.shade(nrm, v)
    jumps = np.abs(np.diff(out, axis=0)).max(axis=0)
    assert np.all(jumps < 0.05 * out.max(axis=0))


def test_shade_mesh_matches_shade(cook):
    env = gradient_env()
    sh = wenv.Shader(env, cook, quality="draft", cache_dir=False)
    rng = np.random.default_rng(2)
    pos = rng.normal(size=(100, 3)).astype(np.float32)
    nrm = unit(rng.normal(size=(100, 3)))
    eye = (3.0, -4.0, 2.0)
    assert np.allclose(sh.shade_mesh(pos, nrm, eye), sh.shade(nrm, unit(np.array(eye, np.float32) - pos)))
    one = sh.shade(nrm, np.array([0, 0, 1], np.float32))  # one view for all
    assert one.shape == (100, 3)


def test_set_environment_and_material_keep_matrices(cook, tmp_path):
    env = gradient_env()
    sh = wenv.Shader(env, wenv.Lambert(0.5), quality="draft", cache_dir=str(tmp_path))
    nnz = sh.stats["rotation_nnz"]
    nrm, v = random_pairs(300, 8)
    sh.set_material(cook)
    sh.set_environment(wenv.Environment(np.full((8, 16, 3), 2.0, np.float32)))
    fresh = wenv.Shader(sh.environment, cook, quality="draft", cache_dir=str(tmp_path))
    assert fresh.stats["cache"] == "loaded" and sh.stats["rotation_nnz"] == nnz
    assert np.array_equal(sh.shade(nrm, v), fresh.shade(nrm, v))


def test_cache_survives_corruption(tmp_path):
    env = gradient_env()
    lam = wenv.Lambert(0.5)
    first = wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path))
    assert first.stats["cache"] == "built"
    (path,) = [p for p in tmp_path.iterdir()]
    nrm, v = random_pairs(200, 9)
    expected = first.shade(nrm, v)
    data = path.read_bytes()
    bad_versions = {
        "truncated": data[: len(data) // 2],
        "empty": b"",
        "flipped": data[:200] + bytes([data[200] ^ 0xFF]) + data[201:],
        "version": data[:8] + b"\x63" + data[9:],
        "tail": data + b"junk",
    }
    for what, blob in bad_versions.items():
        path.write_bytes(blob)
        again = wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path))
        assert again.stats["cache"] == "built", what
        assert np.array_equal(again.shade(nrm, v), expected), what
    assert wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path)).stats["cache"] == "loaded"
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]


def forge_first_block(data, value):
    """The cache file `data` with its first matrix's last value set to `value`, every CRC valid."""
    import zlib
    head, ns = data[:48], SMALL["normals"] ** 2
    entries = [list(struct.unpack_from("<QQII", data, 48 + 24 * s)) for s in range(ns)]
    start, old_size = 48 + 24 * ns, entries[0][0]
    raw = bytearray(zlib.decompress(data[start:start + old_size]))
    raw[-4:] = struct.pack("<f", value)
    block = zlib.compress(bytes(raw))
    entries[0] = [len(block), len(raw), zlib.crc32(raw), 0]
    table = b"".join(struct.pack("<QQII", *e) for e in entries)
    crc = zlib.crc32(table, zlib.crc32(head[:12] + b"\0\0\0\0" + head[16:]))
    return head[:12] + struct.pack("<I", crc) + head[16:] + table + block + data[start + old_size:]


def test_cache_with_valid_crcs_but_impossible_values_is_rebuilt(tmp_path):
    """A block whose CRCs are right but whose values no rotation matrix can hold (|R_ij| <= sqrt of
    its rows) is not loaded: the matrices are rebuilt and shade as before.  A value within the
    bound still loads (the check is the bound, not a guess)."""
    env, lam = gradient_env(), wenv.Lambert(0.5)
    first = wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path))
    (path,) = list(tmp_path.iterdir())
    nrm, v = random_pairs(200, 9)
    expected, data = first.shade(nrm, v), path.read_bytes()
    path.write_bytes(forge_first_block(data, 0.5))
    assert wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path)).stats["cache"] == "loaded"
    for value in (1e30, -1e3, SMALL["local"] * 1.01):
        path.write_bytes(forge_first_block(data, value))
        again = wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path))
        assert again.stats["cache"] == "built", value
        assert np.array_equal(again.shade(nrm, v), expected), value


def test_cache_writes_never_follow_a_planted_link_and_concurrent_writers_agree(tmp_path):
    """The temporary file is created exclusively under a name no one can guess: a symlink planted at
    the name wenv once used (<cache>.tmp.<pid>) is left alone, its target untouched; threads saving
    the same matrices at once all succeed and leave one valid file."""
    env, lam = gradient_env(), wenv.Lambert(0.5)
    wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path))
    (path,) = list(tmp_path.iterdir())
    path.unlink()
    precious = tmp_path.parent / (tmp_path.name + "-precious")
    precious.write_bytes(b"keep me")
    planted = tmp_path / f"{path.name}.tmp.{os.getpid()}"
    planted.symlink_to(precious)
    assert wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path)).stats["cache"] == "built"
    assert precious.read_bytes() == b"keep me" and path.is_file() and not path.is_symlink()
    planted.unlink()
    path.unlink()

    import threading
    results = []

    def build():
        results.append(wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path)).stats["cache"])

    threads = [threading.Thread(target=build) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 4 and set(results) <= {"built", "loaded"}, results  # no "built (save failed)"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    assert wenv.Shader(env, lam, quality=SMALL, cache_dir=str(tmp_path)).stats["cache"] == "loaded"


def _build_in_a_process(cache_dir, start, results):
    """A spawned process's work: wait for the others, then build (or load) the draft matrices in
    `cache_dir` and shade; one thread each, so the processes run side by side on any machine."""
    import wenv as core
    core.set_num_threads(1)
    start.wait(120)
    shader = core.Shader(gradient_env(), core.Lambert(0.5), quality="draft", method="rotation",
                         cache_dir=cache_dir)
    results.put((shader.stats["cache"], shader.shade(*random_pairs(200, 9))))


def test_processes_building_the_same_matrices_at_once_leave_one_valid_cache_file(tmp_path):
    """Processes sharing a cache folder (two Blender sessions, a render farm's nodes) build the same
    matrices at once: each writes its own temporary file and renames it over the cache file, so all
    succeed, one file is left (no temporary ones), and it loads and shades as matrices built
    without a cache."""
    import multiprocessing
    n = 4
    ctx = multiprocessing.get_context("spawn")
    start, results = ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_build_in_a_process, args=(str(tmp_path), start, results)) for _ in range(n)]
    for p in procs:
        p.start()
    try:
        got = [results.get(timeout=300) for _ in range(n)]
    finally:
        for p in procs:
            p.join(60)
    assert [p.exitcode for p in procs] == [0] * n
    nrm, v = random_pairs(200, 9)
    expected = wenv.Shader(gradient_env(), wenv.Lambert(0.5), quality="draft", method="rotation",
                           cache_dir=False).shade(nrm, v)
    assert {use for use, _ in got} <= {"built", "loaded"}, [use for use, _ in got]  # no "built (save failed)"
    for _, rgb in got:
        assert np.array_equal(rgb, expected)
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and ".tmp" not in files[0].name, [f.name for f in files]
    again = wenv.Shader(gradient_env(), wenv.Lambert(0.5), quality="draft", method="rotation",
                        cache_dir=str(tmp_path))
    assert again.stats["cache"] == "loaded"
    assert np.array_equal(again.shade(nrm, v), expected)


def test_progress_reports_and_cancels(one_thread):
    env = gradient_env()
    seen = []
    wenv.Shader(env, wenv.Lambert(0.5), quality=dict(SMALL, normals=16), cache_dir=False, progress=seen.append)
    # reported from one thread as work finishes, rising, ending near complete
    assert len(seen) >= 2 and seen == sorted(seen) and 0 < seen[0] and seen[-1] > 0.9
    with pytest.raises(wenv.CancelledError):
        wenv.Shader(env, wenv.Lambert(0.5), quality=dict(SMALL, normals=16), cache_dir=False,
                    progress=lambda f: True)

    def boom(f):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        wenv.Shader(env, wenv.Lambert(0.5), quality=dict(SMALL, normals=16), cache_dir=False, progress=boom)
    # a return value that cannot be tested for truth stops the work with its own exception
    with pytest.raises(ValueError, match="truth value of an array"):
        wenv.Shader(env, wenv.Lambert(0.5), quality=dict(SMALL, normals=16), cache_dir=False,
                    progress=lambda f: np.array([1, 2]))


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_a_stop_asked_at_the_last_report_is_honoured(method, cook):
    """Thread 0 reports as items finish, and a dynamic schedule may give all of a short loop's last
    items to the other thread; the last report, 1, comes from the calling thread after the loop,
    so a stop asked for there is never lost (before, a cancel of a short set_material was ignored
    now and then on a busy machine).  Repeated, so that either thread takes the last item."""
    env = gradient_env()
    seen, stop_at_end = [], []

    def progress(fraction):
        seen.append(fraction)
        return bool(stop_at_end) and fraction >= 1.0

    shader = wenv.Shader(env, cook, quality="draft", method=method, cache_dir=False, progress=progress)
    assert seen and seen[-1] == 1.0
    nrm, v = random_pairs(200, 16)
    before = shader.shade(nrm, v)
    stop_at_end.append(1)
    new = wenv.CookTorrance(diffuse=0.2, lobes=[{"alpha": 0.4}])
    for _ in range(20):
        seen.clear()
        with pytest.raises(wenv.CancelledError, match="material precomputation cancelled"):
            shader.set_material(new)
        assert seen[-1] == 1.0 and shader.material is cook
    assert np.array_equal(shader.shade(nrm, v), before)
    if method == "rotation":  # the matrices' build (no cache) ends the same way
        with pytest.raises(wenv.CancelledError, match="rotation matrix precomputation cancelled"):
            wenv.Shader(env, cook, quality=dict(SMALL, normals=16), method="rotation", cache_dir=False,
                        progress=progress)
    reported = []
    with pytest.raises(wenv.CancelledError, match="reference cancelled"):
        wenv.reference(env, cook, nrm[:3], v[:3], progress=lambda f: reported.append(f) or f >= 1.0)
    assert reported[-1] == 1.0


def test_set_num_threads_is_honoured(cook):
    env = gradient_env()
    nrm, v = random_pairs(1000, 11)
    old = wenv.get_num_threads()
    try:
        wenv.set_num_threads(1)
        assert wenv.get_num_threads() == 1
        a = wenv.Shader(env, cook, quality="draft", cache_dir=False).shade(nrm, v)
        wenv.set_num_threads(2)
        b = wenv.Shader(env, cook, quality="draft", cache_dir=False).shade(nrm, v)
    finally:
        wenv.set_num_threads(old)
    assert np.allclose(a, b, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError):
        wenv.set_num_threads(0)


@pytest.mark.parametrize("method,quality", [("rotation", "draft"), ("slicing", "default"), ("slicing", "high"),
                                            (None, "auto")])
def test_results_do_not_depend_on_the_number_of_threads(method, quality):
    """Colours, the reference and gloss readings to the bit with 1, 2, 3 or 8 threads (more threads
    than cores included): every sum over the image or the mesh is made in an order of its own."""
    env = wenv.load_environment(hdri_path("city"))
    mat = wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.3, coat_weight=0.5, sheen_weight=0.3)
    nrm, v = random_pairs(600, 3)
    meter = wenv.Glossmeter(60)
    old = wenv.get_num_threads()
    runs = []
    try:
        for threads in (1, 2, 3, 8):
            wenv.set_num_threads(threads)
            kw = {"method": method} if method else {"target_error": 0.02}
            shaded = wenv.Shader(env, mat, quality=quality, cache_dir=False, **kw).shade(nrm, v)
            extra = (wenv.reference(env, mat, nrm[:50], v[:50]), meter.measure(mat)) if method is None else ()
            runs.append((shaded,) + extra)
    finally:
        wenv.set_num_threads(old)
    for run in runs[1:]:
        for got, first in zip(run, runs[0]):
            assert np.array_equal(got, first)


def test_thread_count_holds_for_work_started_from_any_thread():
    """OpenMP keeps its thread count per calling thread; wenv's applies to work started from any
    thread (the add-on shades from workers), read from the work's own parallel region."""
    import threading
    old = wenv.get_num_threads()
    seen = []

    def work():
        seen.append(wenv._work_threads())

    try:
        for n in (1, 2):
            wenv.set_num_threads(n)
            worker = threading.Thread(target=work)
            worker.start()
            worker.join()
            assert seen[-1] == n and wenv._work_threads() == n
    finally:
        wenv.set_num_threads(old)


def test_concurrent_calls_on_one_shader_work_or_say_it_is_busy(cook):
    """Threads sharing one Shader: each call either shades (the same result as alone) or raises
    RuntimeError('Shader is busy in another thread'); nothing else, and the Shader stays usable."""
    import threading
    env = gradient_env()
    shader = wenv.Shader(env, cook, quality="draft", cache_dir=False)
    nrm, v = random_pairs(20000, 31)
    expected = shader.shade(nrm, v)
    outcomes = []

    def hammer(k):
        for i in range(6):
            try:
                if (k + i) % 3 == 2:
                    shader.set_material(cook)
                    outcomes.append("set")
                else:
                    outcomes.append(np.array_equal(shader.shade(nrm, v), expected))
            except RuntimeError as exc:
                assert "busy in another thread" in str(exc)
                outcomes.append("busy")

    threads = [threading.Thread(target=hammer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(outcomes) == 24 and False not in outcomes
    assert np.array_equal(shader.shade(nrm, v), expected)


def test_reference_constant_environment():
    env = wenv.Environment(np.full((64, 128, 3), 1.0, np.float32))
    nrm, v = random_pairs(50, 12)
    out = wenv.reference(env, wenv.Lambert((0.5, 0.25, 1.0)), nrm, v)
    assert np.allclose(out, [0.5, 0.25, 1.0], rtol=2e-3)


@pytest.mark.parametrize("quality, message", [
    ({"global": 48}, "global"), ({"global": -64}, "global"), ({"local": 3}, "local"),
    ({"local": 1 << 20}, "local"), ({"normals": 7}, "normals"), ({"views": 0}, "views"),
    ({"coefficients": 10**9}, "coefficients"), ({"matrix_epsilon": float("nan")}, "matrix_epsilon"),
    ({"bogus": 1}, "bogus"), ("ultra", "quality"), ({"lights": 5000}, "lights"), ({"lights": -1}, "lights"),
    ({"light_threshold": 0.5}, "light_threshold"), ({"light_threshold": float("inf")}, "light_threshold"),
    ({"grazing": -1.0}, "grazing"), ({"grazing": float("nan")}, "grazing"), ({"grazing": 1e3}, "grazing"),
    ({"grazing": "yes"}, "grazing"), ({"light_tolerance": 0.0}, "light_tolerance"),
    ({"light_tolerance": float("nan")}, "light_tolerance"), ({"light_tolerance": 2.0}, "light_tolerance"),
    ({"grazing_slopes": 2}, "grazing_slopes"), ({"grazing_slopes": -1}, "grazing_slopes"),
    ({"lobe_rings": 9}, "lobe_rings"), ({"lobe_rings": -1}, "lobe_rings"),
])
def test_bad_quality(quality, message):
    env = gradient_env()
    with pytest.raises((ValueError, TypeError), match=message):
        wenv.Shader(env, wenv.Lambert(0.5), quality=quality, cache_dir=False)


@pytest.mark.parametrize("method", wenv.METHODS)
def test_bad_arguments(method, cook):
    env = gradient_env()
    sh = wenv.Shader(env, cook, quality="draft", method=method, cache_dir=False)
    good = unit([[0, 0, 1]] * 4)
    with pytest.raises(TypeError, match="normals"):
        sh.shade(good.astype(np.float64), good)
    with pytest.raises(ValueError, match="view_dirs"):
        sh.shade(good, good[:3])
    with pytest.raises(ValueError, match="normals"):
        sh.shade(np.zeros((4, 3), np.float32), good)
    with pytest.raises(ValueError, match="view_dirs"):
        sh.shade(good, np.full((4, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="normals"):
        sh.shade(np.ones((4, 2), np.float32), good)
    with pytest.raises(TypeError, match="normals"):
        sh.shade("not an array", good)
    with pytest.raises(ValueError, match="eye"):
        sh.shade_mesh(np.zeros((1, 3), np.float32), good[:1], (0.0, 0.0, 0.0))
    with pytest.raises(TypeError, match="env"):
        sh.set_environment("sunset")
    with pytest.raises(TypeError, match="material"):
        sh.set_material(None)
    with pytest.raises(TypeError, match="env"):
        wenv.Shader("env", cook, method=method)
    with pytest.raises(TypeError, match="material"):
        wenv.Shader(env, "material", method=method)
    with pytest.raises(TypeError, match="progress"):
        wenv.Shader(env, cook, method=method, progress=3)
    if method == "rotation":  # the only method with a cache
        with pytest.raises(OSError, match="cache_dir"):
            wenv.Shader(env, cook, quality="draft", method=method, cache_dir="/nonexistent/folder")
    assert sh.shade(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)).shape == (0, 3)


def test_bad_method_and_reference_arguments(cook):
    env = gradient_env()
    good = unit([[0, 0, 1]] * 4)
    with pytest.raises(ValueError, match="method"):
        wenv.Shader(env, cook, method="magic")
    with pytest.raises(ValueError, match="view_dirs"):
        wenv.reference(env, cook, good[:2], good[:3])


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_results_do_not_depend_on_earlier_materials_or_lighting(method, cook):
    """A shader that shaded with other settings before gives what a fresh one gives."""
    sharp = wenv.CookTorrance(diffuse=(0.1, 0.2, 0.3), lobes=[{"specular": (1, 1, 1), "alpha": 0.05, "ior": 1.6}])
    lambert = wenv.Lambert((0.5, 0.4, 0.3))
    env_a, env_b = gradient_env(), gradient_env().with_transform(rotation=1.0, strength=2.0)
    nrm, v = random_pairs(1500, 9)
    sh = wenv.Shader(env_a, sharp, quality=SMALL, method=method, cache_dir=False)
    for env, mat in [(env_a, cook), (env_b, lambert), (env_b, cook), (env_a, sharp)]:
        sh.shade(nrm, v)
        sh.set_environment(env)
        sh.set_material(mat)
        fresh = wenv.Shader(env, mat, quality=SMALL, method=method, cache_dir=False).shade(nrm, v)
        assert np.array_equal(sh.shade(nrm, v), fresh)


def sun_env(h=64, w=128, peak=2e4):
    """A dim sky with a small sun of a few pixels, as the bundled sunrise has."""
    rows, cols = np.mgrid[0:h, 0:w]
    img = np.empty((h, w, 3), np.float32)
    img[..., 0] = 0.4 + 0.2 * np.cos(2 * np.pi * cols / w)
    img[..., 1] = 0.3 + 0.3 * rows / h
    img[..., 2] = 0.5
    img[20:22, 40:42] = (peak, 0.9 * peak, 0.8 * peak)
    return wenv.Environment(img)


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_sun_is_shaded_as_exact_lights(method):
    """The sun's pixels leave the wavelet lighting and are shaded per vertex: far closer to the
    reference than the same setting without lights, diffuse and glossy."""
    env = sun_env()
    nrm, v = random_pairs(1500, seed=3)
    q = dict(SMALL, light_coefficients=0)
    for mat in (wenv.Lambert(0.8), wenv.CookTorrance(diffuse=0.1, lobes=[{"specular": 1, "alpha": 0.1, "ior": 1.5}])):
        ref = wenv.reference(env, mat, nrm, v)
        lit = wenv.Shader(env, mat, quality=dict(q, lights=16), method=method, cache_dir=False)
        unlit = wenv.Shader(env, mat, quality=dict(q, lights=0), method=method, cache_dir=False)
        assert lit.stats["direct_lights"] >= 1 and unlit.stats["direct_lights"] == 0
        err = [float(np.sqrt(np.mean((s.shade(nrm, v) - ref) ** 2) / np.mean(ref ** 2))) for s in (lit, unlit)]
        assert err[0] < 0.1 * err[1], err
        assert err[0] < (0.002 if isinstance(mat, wenv.Lambert) else 0.02), err  # measured 0.03 % and 0.6 %


def test_lights_keep_a_constant_environment_exact():
    """No pixel of a constant environment is brighter than its mean: nothing is taken out and the
    result stays exact."""
    env = wenv.Environment(np.full((32, 64, 3), 1.3, np.float32))
    nrm, v = random_pairs(500)
    sh = wenv.Shader(env, wenv.Lambert(0.5), quality=dict(SMALL, lights=8), cache_dir=False)
    assert sh.stats["direct_lights"] == 0
    assert np.allclose(sh.shade(nrm, v), 0.65, rtol=2e-6)


def test_messages_show_the_numbers_they_quote():
    """Messages with floating-point values print the values (Python's own formatter has no %g: a
    literal '%g' once stood in for them)."""
    env = gradient_env()
    cases = [(lambda: wenv.Shader(env, wenv.Lambert(0.5), quality="auto", target_error=2.5), "got 2.5"),
             (lambda: wenv.Shader(env, wenv.Lambert(0.5), memory_budget_mb=-3.0), "got -3"),
             (lambda: wenv.Environment(np.ones((4, 8, 3), np.float32), strength=-1.5), "got -1.5"),
             (lambda: wenv.CookTorrance(lobes=[{"alpha": -0.5}]), "got -0.5")]
    for make, text in cases:
        with pytest.raises(ValueError) as info:
            make()
        assert text in str(info.value) and "%" not in str(info.value), str(info.value)


def test_radiance_beyond_float32_shading_is_refused_and_below_it_shades_right():
    """Lighting whose reflection float32 cannot hold is a ValueError (an OSError from a file): finite
    values near FLT_MAX once shaded to 0 and strength=1e308 to inf.  Just below the limit, a sun of
    1e17 over a dim sky shades finite and as the reference does."""
    sky = np.full((32, 64, 3), 0.5, np.float32)
    with pytest.raises(ValueError, match=r"pixels: the brightest pixel times strength is 3e\+38"):
        wenv.Environment(np.full((4, 8, 3), 3e38, np.float32))
    with pytest.raises(ValueError, match=r"strength is 5e\+307"):
        wenv.Environment(sky, strength=1e308)
    with pytest.raises(ValueError, match=r"^strength: .* 5e\+19"):
        wenv.Environment(sky).with_transform(strength=1e20)
    sun = sky.copy()
    sun[6:8, 20:22] = 1e17
    env = wenv.Environment(sun)
    mat = wenv.CookTorrance(diffuse=0.3, lobes=[{"alpha": 0.3}])
    nrm, v = random_pairs(400, 21)
    out, ref = wenv.Shader(env, mat, quality="draft").shade(nrm, v), wenv.reference(env, mat, nrm, v)
    assert np.all(np.isfinite(out)) and out.max() > 1e13
    assert np.sqrt(np.mean((out - ref) ** 2) / np.mean(ref ** 2)) < 0.02


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_a_shader_keeps_the_materials_set_before_it(method, tmp_path):
    """Meshes of a few materials shaded in turn: a material among the last 40 set (made again from the
    same values counts) is set again without making anything, and shades exactly as a shader made
    for it; one more puts out the oldest; a new lighting keeps them, their table rows made again for
    it; one value apart is another material."""
    kept = 40  # the wavelet shader's (docs/python.md, "Cache, progress and kept materials")
    env, dusk = gradient_env(), wenv.Environment(gradient_env().pixels[:, ::-1].copy())
    made = [dict(diffuse=0.01 * k, lobes=[{"alpha": 0.2 + 0.01 * k}]) for k in range(kept + 1)]
    mats = [wenv.CookTorrance(**m) for m in made]
    nrm, v = random_pairs(300, 5)

    def own(lighting, k):
        return wenv.Shader(lighting, mats[k], quality="draft", method=method, cache_dir=tmp_path).shade(nrm, v)

    shader = wenv.Shader(env, mats[0], quality="draft", method=method, cache_dir=tmp_path)
    for k in range(1, kept):
        shader.set_material(mats[k])
    assert (shader.stats["materials_kept"], shader.stats["materials_reused"]) == (kept, 0)
    for k in (0, 2, 1, 3):
        shader.set_material(wenv.CookTorrance(**made[k]))
        assert np.array_equal(shader.shade(nrm, v), own(env, k))
    assert shader.stats["materials_reused"] == 4
    shader.set_material(mats[kept])  # the oldest, 4, goes
    shader.set_material(mats[4])  # made again; 5 goes
    assert (shader.stats["materials_kept"], shader.stats["materials_reused"]) == (kept, 4)
    shader.set_environment(dusk)
    for k in (3, kept, 1):
        shader.set_material(mats[k])
        assert np.array_equal(shader.shade(nrm, v), own(dusk, k))
    assert shader.stats["materials_reused"] == 7
    shader.set_material(wenv.CookTorrance(diffuse=0.03, lobes=[{"alpha": 0.23 + 1e-9}]))
    assert shader.stats["materials_reused"] == 7 and not np.array_equal(shader.shade(nrm, v), own(dusk, 3))


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_a_new_material_reports_progress_and_a_cancel_keeps_the_old_one(method, cook, one_thread):
    """A material's BRDF slices cost its lobes' evaluations (dozens of lobes: seconds), so
    set_material reports progress through the Shader's callback, rising to 1, and a cancel leaves
    the Shader shading its previous material, as the peer methods do."""
    env = gradient_env()
    seen, stop = [], []

    def progress(fraction):
        seen.append(fraction)
        return bool(stop)

    shader = wenv.Shader(env, cook, quality="draft", method=method, cache_dir=False, progress=progress)
    nrm, v = random_pairs(300, 14)
    before = shader.shade(nrm, v)
    many = wenv.CookTorrance(diffuse=0.0, lobes=[dict(specular=0.04, alpha=0.05 + 0.02 * i) for i in range(12)])
    seen.clear()
    shader.set_material(many)
    assert len(seen) > 10 and seen == sorted(seen) and seen[-1] > 0.95
    after = shader.shade(nrm, v)
    assert not np.allclose(after, before)
    stop.append(1)
    new = wenv.CookTorrance(diffuse=0.2, lobes=[{"alpha": 0.4}])
    with pytest.raises(wenv.CancelledError, match="material precomputation cancelled"):
        shader.set_material(new)
    assert shader.material is many and np.array_equal(shader.shade(nrm, v), after)
    # a material set before is kept: setting it again makes nothing, so there is nothing to cancel
    shader.set_material(cook)
    assert np.array_equal(shader.shade(nrm, v), before)
    stop.clear()
    shader.set_material(new)
    assert not np.allclose(shader.shade(nrm, v), before)
