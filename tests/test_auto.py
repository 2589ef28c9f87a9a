"""quality="auto": picks the cheapest ladder level (or, without lobes, SH order) predicted to meet
target_error, never builds rotation matrices, keeps within its memory budget, and meets its target (benchmarks/auto_quality.py
shows it on every bundled HDRI; here on a reduced one)."""
import json
import os
import threading

import numpy as np
import pytest

import wenv
from conftest import hdri_path
from tests.helpers.measure import relative_rmse


def unit(a):
    a = np.asarray(a, np.float64)
    return (a / np.linalg.norm(a, axis=-1, keepdims=True)).astype(np.float32)


def small_sunset():
    """Sunset box-filtered to 64 x 128 pixels."""
    px = wenv.load_environment(hdri_path("sunset")).pixels[..., :3]
    f = px.shape[0] // 64
    return wenv.Environment(np.ascontiguousarray(px.reshape(64, f, 128, f, 3).mean(axis=(1, 3)), np.float32))


@pytest.fixture(scope="module")
def sunset():
    return small_sunset()


def glossy(m):
    return wenv.CookTorrance(diffuse=0.1, lobes=[{"specular": 1, "alpha": m, "ior": 1.5}])


def test_lambert_builds_no_matrices(sunset):
    """Without lobes auto takes spherical harmonics (no matrices, no slices); a target beyond the
    highest SH order falls back to the slicing ladder, which builds none either."""
    sh = wenv.Shader(sunset, wenv.Lambert(0.7), quality="auto")
    info = sh.stats["auto"]
    assert sh.method == "sh" and info["method"] == "sh" and info["level"] is None
    assert info["sh_order"] in wenv.AUTO_SH_ORDERS and sh.quality["order"] == info["sh_order"]
    assert info["met"] and info["predicted_error"] <= 0.01
    fine = wenv.Shader(sunset, wenv.Lambert(0.7), quality="auto", target_error=1e-4)
    assert fine.method == "slicing" and fine.stats["rotation_nnz"] == 0
    assert fine.quality == wenv.AUTO_LADDER[fine.stats["auto"]["level"]]


def cost_rank(info):
    """SH orders are cheaper than every ladder level."""
    return (0, info["sh_order"]) if info["method"] == "sh" else (1, info["level"])


def test_tighter_targets_never_pick_cheaper_levels(sunset):
    for mat in (wenv.Lambert(0.7), glossy(0.05), glossy(0.2), glossy(0.5)):
        ranks = [cost_rank(wenv.Shader(sunset, mat, quality="auto", target_error=t).stats["auto"])
                 for t in (0.3, 0.1, 0.03, 0.01, 0.003, 1e-4)]
        assert ranks == sorted(ranks), ranks
    # narrower lobes need more at the same target
    assert (wenv.Shader(sunset, glossy(0.1), quality="auto", target_error=0.05).stats["auto"]["level"]
            > wenv.Shader(sunset, glossy(0.5), quality="auto", target_error=0.05).stats["auto"]["level"])


def test_lambert_error_is_predicted_from_the_lighting_spectrum(sunset):
    """The SH irradiance error auto predicts is the measured one, not just a bound: the measured
    error is 0.9 - 1.0 times it at every order auto picks here (uniform normals, as the prediction
    assumes; 0.95 - 0.985 when written).  A floor added linearly instead of in quadrature put it at
    0.8 - 0.95 and made auto pick an order too high on the bundled HDRIs."""
    nrm = unit(np.random.default_rng(3).normal(size=(3000, 3)))
    mat = wenv.Lambert((0.8, 0.6, 0.3))
    ref = wenv.reference(sunset, mat, nrm, nrm)
    ratios = []
    for target in (0.05, 0.02, 0.01, 0.005, 0.003, 0.002):
        sh = wenv.Shader(sunset, mat, quality="auto", target_error=target)
        info = sh.stats["auto"]
        if info["method"] != "sh":
            continue
        err = float(np.sqrt(np.mean((sh.shade(nrm, nrm) - ref) ** 2) / np.mean(ref ** 2)))
        ratios.append(err / info["predicted_error"])
        assert err <= target
    assert len(ratios) >= 5 and 0.9 <= min(ratios) and max(ratios) <= 1.0, ratios


def test_memory_budget_is_kept(sunset):
    tight = wenv.Shader(sunset, glossy(0.05), quality="auto", target_error=0.001, memory_budget_mb=64)
    info = tight.stats["auto"]
    assert not info["met"] and info["level_mb"] <= 64
    big = wenv.Shader(sunset, glossy(0.05), quality="auto", target_error=0.001, memory_budget_mb=4096)
    assert big.stats["auto"]["level"] > info["level"]


@pytest.mark.parametrize("m, target", [(None, 0.01), (0.5, 0.03), (0.2, 0.08)])
def test_meets_its_target(sunset, m, target):
    rng = np.random.default_rng(7)
    nrm = unit(rng.normal(size=(400, 3)))
    v = unit(rng.normal(size=(400, 3)))
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    mat = wenv.Lambert(0.7) if m is None else glossy(m)
    sh = wenv.Shader(sunset, mat, quality="auto", target_error=target)
    ref = wenv.reference(sunset, mat, nrm, v)
    err = float(np.sqrt(np.mean((sh.shade(nrm, v) - ref) ** 2) / np.mean(ref ** 2)))
    assert err <= target, (err, sh.stats["auto"])


def test_the_default_preset_is_a_level():
    """Level 3 is the default preset (the grazing path, suns read to 5 %): within 1 % at m = 0.1 under
    sunset (benchmarks/auto_quality.py measures 0.3 %) in about half the first-view time of level 4,
    which errs 2.9 % there, so a 1 % target takes it -- and meets it."""
    assert wenv.AUTO_LADDER[3] == wenv.QUALITY_PRESETS["default"]
    sunset = wenv.load_environment(hdri_path("sunset"))
    sh = wenv.Shader(sunset, glossy(0.1), quality="auto", target_error=0.01)
    a = sh.stats["auto"]
    assert a["level"] == 3 and a["met"] and sh.quality == wenv.QUALITY_PRESETS["default"], a
    rng = np.random.default_rng(5)
    nrm = unit(rng.normal(size=(400, 3)))
    v = unit(rng.normal(size=(400, 3)))
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    ref = wenv.reference(sunset, glossy(0.1), nrm, v)
    assert np.sqrt(np.mean((sh.shade(nrm, v) - ref) ** 2) / np.mean(ref ** 2)) <= 0.01


def test_does_not_claim_a_target_no_level_meets():
    """Studio's softboxes as 4096 exact lights take 94 % of its flux and dominate the signal, which
    drives the last level's (high's) predicted error toward zero; it measures about 0.03-0.05 % at
    m = 0.1, so a target of 0.01 % is out of reach and auto must say so (taking the most accurate
    level)."""
    studio = wenv.load_environment(hdri_path("studio"))
    a = wenv.Shader(studio, glossy(0.1), quality="auto", target_error=1e-4).stats["auto"]
    assert a["met"] is False and a["level"] == len(wenv.AUTO_LADDER) - 1 and a["predicted_error"] > 1e-4
    rng = np.random.default_rng(3)
    nrm = unit(rng.normal(size=(200, 3)))
    v = unit(rng.normal(size=(200, 3)))
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    sh = wenv.Shader(studio, glossy(0.1), quality=wenv.AUTO_LADDER[-1], method="slicing")
    ref = wenv.reference(studio, glossy(0.1), nrm, v)
    assert np.sqrt(np.mean((sh.shade(nrm, v) - ref) ** 2) / np.mean(ref ** 2)) > 1e-4


def test_high_is_not_claimed_where_bright_features_remain():
    """`high` takes courtyard's sunlit walls out as clustered lights, which still err where the walls
    were: benchmarks/auto_quality.py measures high at 2.2 % (m = 0.05) and 1.0 % (m = 0.5) there, so
    auto must not claim 1 %.  Under sunset, a smooth sky, high measures 0.3 % at m = 0.1: claimed."""
    courtyard, sunset = (wenv.load_environment(hdri_path(h)) for h in ("courtyard", "sunset"))
    for m in (0.05, 0.5):
        a = wenv.Shader(courtyard, glossy(m), quality="auto", target_error=0.01).stats["auto"]
        assert a["met"] is False and a["level"] == len(wenv.AUTO_LADDER) - 1 and a["predicted_error"] > 0.01, (m, a)
    assert wenv.Shader(sunset, glossy(0.1), quality="auto", target_error=0.01).stats["auto"]["met"] is True


def test_every_level_is_estimated():
    """Each level's estimate: lights take their share of the flux, and under a narrow lobe a sun's
    reflection dominates the signal (so the relative error of the rest shrinks) more than under a
    wide one.  The ladder ends at the high preset."""
    sky = np.full((64, 128, 3), 0.5, np.float32)
    sun = sky.copy()
    sun[12, 40] = 2e5
    info = {(name, m): wenv.Shader(wenv.Environment(env), glossy(m), quality="auto").stats["auto"]
            for name, env in (("sky", sky), ("sun", sun)) for m in (0.1, 0.5)}
    for a in info.values():
        assert len(a["levels"]) == len(wenv.AUTO_LADDER)
    narrow, wide = info["sun", 0.1]["levels"], info["sun", 0.5]["levels"]
    for lv in range(len(wenv.AUTO_LADDER)):
        assert 0.5 < narrow[lv]["lights_share"] < 1 and narrow[lv]["light_dominance"] > 2 * wide[lv]["light_dominance"] > 0
        assert info["sky", 0.1]["levels"][lv]["lights_share"] == 0 == info["sky", 0.1]["levels"][lv]["light_dominance"]
        assert narrow[lv]["predicted_error"] < info["sky", 0.1]["levels"][lv]["predicted_error"]
    assert wenv.AUTO_LADDER[-1] == wenv.QUALITY_PRESETS["high"]


def test_each_level_takes_its_brightest_pixels():
    """Each level's lights are the brightest pixels above its threshold, up to its budget: with 300
    candidates of distinct radiance in random order, the flux share of levels 0 and 1 is that of
    the 64 and 128 brightest, and levels 2 - 6 take all 300."""
    rng = np.random.default_rng(11)
    img = np.full((256, 512, 3), 0.01, np.float32)
    where = rng.choice(img.shape[0] * img.shape[1], 300, replace=False)
    radiance = 1000.0 + rng.permutation(300) * 3.0
    img.reshape(-1, 3)[where] = radiance[:, None]
    env = wenv.Environment(img)
    flux = img.mean(axis=2).ravel() * np.asarray(env.solid_angles(), np.float64).ravel()
    brightest = where[np.argsort(-radiance)]
    levels = wenv.Shader(env, glossy(0.2), quality="auto").stats["auto"]["levels"]
    for level, count in zip(levels, (64, 128, 300, 300, 300, 300, 300), strict=True):
        assert level["lights_share"] == pytest.approx(flux[brightest[:count]].sum() / flux.sum(), rel=1e-4)


def test_bad_arguments(sunset):
    for t in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="target_error"):
            wenv.Shader(sunset, wenv.Lambert(0.5), quality="auto", target_error=t)
    with pytest.raises(ValueError, match="memory_budget"):
        wenv.Shader(sunset, wenv.Lambert(0.5), quality="auto", memory_budget_mb=0.01)
    with pytest.raises(ValueError, match="auto"):
        wenv.Shader(sunset, wenv.Lambert(0.5), quality="auto", method="rotation")
    with pytest.raises(TypeError):
        wenv.Shader(sunset, wenv.Lambert(0.5), quality="auto", target_error="1%")


def test_mesh_normals_count_only_the_slices_they_need(sunset):
    """A flat floor reads a handful of normal samples, a sphere all of them: within the same budget
    the floor affords a finer setting."""
    mat = glossy(0.05)
    floor = np.tile(np.float32([[0.0, 0.0, 1.0]]), (1000, 1))
    sphere = unit(np.random.default_rng(0).normal(size=(5000, 3)))
    a_floor = wenv.Shader(sunset, mat, quality="auto", target_error=0.001, memory_budget_mb=100,
                          normals=floor).stats["auto"]
    a_sphere = wenv.Shader(sunset, mat, quality="auto", target_error=0.001, memory_budget_mb=100,
                           normals=sphere).stats["auto"]
    assert a_floor["used_normal_samples"] <= 4 and a_sphere["used_normal_samples"] > 500
    assert a_floor["level"] > a_sphere["level"] and a_floor["level_mb"] <= 100 and a_sphere["level_mb"] <= 100
    with pytest.raises(ValueError, match="normals"):
        wenv.Shader(sunset, mat, quality="default", normals=floor)
    with pytest.raises(ValueError, match="normals"):
        wenv.Shader(sunset, mat, quality="auto", normals=np.zeros((3, 3), np.float32))


def test_the_environment_is_analysed_once():
    """What auto reads of an environment is made on first need and kept with it, in two parts: the
    lights and the pyramid for materials with lobes, the SH spectrum for those without.  Later
    choices for other materials and targets read it and choose exactly as a first choice would.  A
    transformed copy is a new environment with its own."""
    env = small_sunset()  # not the shared fixture: other tests have analysed that one
    first = wenv.Shader(env, glossy(0.1), quality="auto", target_error=0.03).stats["auto"]
    assert first["analysis_seconds"] > 0 and first["seconds"] >= first["analysis_seconds"]
    # the first lobe-less choice makes the spectrum, the later ones read it
    lambert = [wenv.Shader(env, wenv.Lambert(0.7), quality="auto", target_error=t).stats["auto"]
               for t in (0.1, 0.01)]
    assert [a["method"] for a in lambert] == ["sh", "sh"]
    assert lambert[0]["analysis_seconds"] > 0 and lambert[1]["analysis_seconds"] == 0
    for mat in (glossy(0.1), glossy(0.5), wenv.Lambert(0.7)):
        for t in (0.1, 0.01, 1e-4):  # 1e-4: no SH order meets it, so Lambert goes to the ladder too
            again = wenv.Shader(env, mat, quality="auto", target_error=t).stats["auto"]
            assert again["analysis_seconds"] == 0
            copy = env.with_transform(rotation=env.rotation, strength=env.strength)
            fresh = wenv.Shader(copy, mat, quality="auto", target_error=t).stats["auto"]
            assert fresh["analysis_seconds"] > 0
            keys = ("level", "sh_order", "method", "met")
            assert {k: again[k] for k in keys} == {k: fresh[k] for k in keys}
            # equal but for the order threads add the SH projection's blocks in
            assert again["predicted_error"] == pytest.approx(fresh["predicted_error"], rel=1e-9)
            assert again["levels"] == fresh["levels"]
    # a rotated copy is analysed anew: its lights' directions, hence the dominance grids, move
    turned = wenv.Shader(env.with_transform(rotation=1.0), glossy(0.1), quality="auto", target_error=0.03).stats["auto"]
    assert turned["analysis_seconds"] > 0


def test_threads_choosing_on_one_environment_make_its_analysis_once():
    """Choices run without the GIL: threads choosing at once on a new environment make each part of
    its analysis once between them and choose alike."""
    env = small_sunset()
    out = {}

    def choose(i):
        mat = glossy(0.2) if i % 2 else wenv.Lambert(0.7)
        out[i] = wenv.Shader(env, mat, quality="auto", target_error=0.02).stats["auto"]

    threads = [threading.Thread(target=choose, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for kind in (0, 1):
        same = [out[i] for i in range(8) if i % 2 == kind]
        assert sum(a["analysis_seconds"] > 0 for a in same) == 1
        assert all({k: a[k] for k in ("level", "sh_order", "predicted_error")}
                   == {k: same[0][k] for k in ("level", "sh_order", "predicted_error")} for a in same)


PRINCIPLED_DATA = os.path.join(os.path.dirname(__file__), "data", "accuracy_reference_principled.npz")


def stored_error(shader, data, key):
    """Relative RMSE over the stored pairs of benchmarks/accuracy.py --principled."""
    return relative_rmse(shader.shade(data["normals"], data["views"]), data[key])


def test_a_ggx_lobe_is_predicted_as_ggx_lobes_err():
    """The levels' errors were measured on Beckmann lobes.  A GGX lobe of the same width (Blender's
    Principled BSDF) errs 2-3x as much where the grazing path's cells take it (default: the
    Principled metal, alpha 0.09, 0.5-2.7 % over the eight HDRIs, Beckmann m = 0.09 0.1-2.7 %; 4-5x
    before the path cut GGX lobes in two), and auto took `default` for that metal at 1 % and said it
    met it (3.4 % under sunset then).  Now each level's prediction carries its measured GGX factor,
    the largest over the HDRIs: under sunset no level is said to meet 1 % that misses it on the
    stored pairs (the median factor said level 5 met it, at 1.5 %), and auto takes one that meets it."""
    data = np.load(PRINCIPLED_DATA)
    sunset = wenv.load_environment(hdri_path("sunset"))
    metal = wenv.Principled(**json.loads(str(data["materials"]))["metal"]["principled"])
    beckmann = wenv.CookTorrance(lobes=[{"specular": 1, "alpha": 0.09, "ior": 1.5}], distribution="beckmann")
    ggx, beck = (wenv.Shader(sunset, m, quality="auto", target_error=0.01).stats["auto"] for m in (metal, beckmann))
    assert ggx["levels"][3]["predicted_error"] > 2 * beck["levels"][3]["predicted_error"]
    for level, q in enumerate(wenv.AUTO_LADDER):
        if ggx["levels"][level]["predicted_error"] <= 0.01:
            fixed = wenv.Shader(sunset, metal, quality=dict(q), method="slicing")
            assert stored_error(fixed, data, "sunset/metal") <= 0.01, level
    sh = wenv.Shader(sunset, metal, quality="auto", target_error=0.01)
    assert sh.stats["auto"]["level"] != 3 and sh.stats["auto"]["met"]
    assert stored_error(sh, data, "sunset/metal") <= 0.01


def test_a_dielectric_ggx_lobe_is_predicted_as_a_dielectric():
    """One GGX factor for every material, calibrated on a metal, predicted a paint 2-4x above what it
    errs, and auto took `high` for it where `default` met 1 %.  The factor now goes by how much of
    its reflection a material keeps head-on (a paint 0.15 of what it keeps at 80 degrees, a metal
    0.87): under every bundled HDRI a paint and a metal said to meet 1 % meet it on the stored
    pairs, and the paint takes a cheaper level than `high` under at least half of them."""
    data = np.load(PRINCIPLED_DATA)
    specs = json.loads(str(data["materials"]))
    cheaper = 0
    for h in json.loads(str(data["hdris"])):
        env = wenv.load_environment(hdri_path(h))
        for name in ("paint", "metal"):
            sh = wenv.Shader(env, wenv.Principled(**specs[name]["principled"]), quality="auto", target_error=0.01)
            a = sh.stats["auto"]
            assert not a["met"] or stored_error(sh, data, f"{h}/{name}") <= 0.01, (h, name, a["level"])
            cheaper += name == "paint" and a["level"] < len(wenv.AUTO_LADDER) - 1 and a["met"]
            assert (a["head_on"] < 0.2) == (name == "paint"), a["head_on"]
    assert cheaper >= 4


def test_a_lobe_narrower_than_the_calibration_is_not_read_at_its_edge():
    """A clear coat of Coat Roughness 0.1 (alpha 0.01) lies below the calibrated widths (m = 0.05 up).
    Read as m = 0.05, auto took level 2 at 3 % under city and said it met it: the coated paint errs
    14.5 % there, since a level without the grazing path loses such a lobe at every view.  With
    the measured factor for narrow lobes it takes a level with the path, within 3 %."""
    data = np.load(PRINCIPLED_DATA)
    city = wenv.load_environment(hdri_path("city"))
    coated = wenv.Principled(**json.loads(str(data["materials"]))["coated"]["principled"])
    sh = wenv.Shader(city, coated, quality="auto", target_error=0.03)
    assert wenv.AUTO_LADDER[sh.stats["auto"]["level"]]["grazing"] > 0 and sh.stats["auto"]["met"]
    assert stored_error(sh, data, "city/coated") <= 0.03
