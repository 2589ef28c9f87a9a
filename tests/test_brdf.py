"""Reflectance models: Lambert and multi-lobe Cook-Torrance (csrc/scene/, python/bind_material.c)."""
import math
import pickle

import numpy as np
import pytest

import wenv

DISTS = ("beckmann", "ggx")
SHADOWS = ("smith", "vcavity")


def direction(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)], np.float32)


def random_upper(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def unit64(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ------------------------------------------------------------------ reference formulas (numpy)

def fresnel_ref(cos_i, n):
    """Unpolarised Fresnel from Snell's law and the s/p amplitudes."""
    cos_i = np.asarray(cos_i, np.float64)
    sin_t = np.sqrt(1 - cos_i**2) / n
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    rp = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (rs**2 + rp**2)


def ndf_ref(dist, m, c):
    t2 = (1 - c**2) / c**2
    if dist == "beckmann":
        return np.exp(-t2 / m**2) / (math.pi * m**2 * c**4)
    return m**2 / (math.pi * c**4 * (m**2 + t2) ** 2)


def lambda_ref(dist, m, c):
    tan = math.sqrt(1 - c * c) / c
    if dist == "ggx":
        return (-1 + math.sqrt(1 + m * m * tan * tan)) / 2
    a = 1 / (m * tan)
    return (math.erf(a) - 1) / 2 + math.exp(-a * a) / (2 * a * math.sqrt(math.pi))


def lobe_ref(dist, shadow, m, ior, wi, wo):
    """F D G / (4 ci co) in float64 from the textbook formulas, rows of wi/wo."""
    wi, wo = unit64(wi), unit64(wo)
    h = unit64(wi + wo)
    ci, co, ch = wi[:, 2], wo[:, 2], h[:, 2]
    cd = np.sum(wi * h, axis=1)
    F = fresnel_ref(cd, ior)
    D = ndf_ref(dist, m, ch)
    if shadow == "smith":
        li = np.array([lambda_ref(dist, m, c) for c in ci])
        lo = np.array([lambda_ref(dist, m, c) for c in co])
        G = 1 / (1 + li + lo)
    else:
        G = np.minimum(1, np.minimum(2 * ch * co / cd, 2 * ch * ci / cd))
    return F * D * G / (4 * ci * co)


# ------------------------------------------------------------------ Fresnel

def test_fresnel_reference_values_of_black_glass():
    # docs/ARCHITECTURE.md §3.7 (the thesis's 0.998 at 60 degrees is a typo).
    for deg, want in ((0, 0.04879), (20, 0.04908), (60, 0.10006), (85, 0.61915)):
        assert wenv._fresnel(math.cos(math.radians(deg)), 1.567) == pytest.approx(want, abs=5e-6)


def test_fresnel_matches_snell_s_and_p_average():
    c = np.linspace(0.0, 1.0, 201)
    for n in (1.0001, 1.33, 1.5, 1.567, 2.4, 10.0):
        got = wenv._fresnel(c, n)
        np.testing.assert_allclose(got, fresnel_ref(c, n), rtol=1e-10, atol=1e-15)
        assert got[0] == pytest.approx(1.0)  # grazing
        assert got[-1] == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12)
        assert np.all((got > 0) & (got <= 1))


# ------------------------------------------------------------------ distributions and Smith Lambda

@pytest.mark.parametrize("dist", DISTS)
def test_ndf_matches_formula(dist):
    c = np.linspace(0.05, 1.0, 40)
    for m in (0.05, 0.3, 1.0, 4.0):
        np.testing.assert_allclose(wenv._ndf(dist, m, c), ndf_ref(dist, m, c), rtol=1e-12)
    assert wenv._ndf(dist, 0.3, 0.0) == 0.0 or dist == "ggx"
    assert wenv._ndf(dist, 0.3, -0.5) == 0.0


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("m", [1e-4, 0.01, 0.1, 0.5, 1.0, 3.0])
def test_ndf_projected_area_is_one(dist, m):
    """Int D(h) cos(theta_h) d omega_h = 1, by Gauss-Legendre in u = atan(tan(theta_h) / m)."""
    z, wz = np.polynomial.legendre.leggauss(400)
    u = (z + 1) * math.pi / 4  # [0, pi/2)
    tan_t = m * np.tan(u)
    theta = np.arctan(tan_t)
    dtheta_du = m / np.cos(u) ** 2 / (1 + tan_t**2)
    f = wenv._ndf(dist, m, np.cos(theta)) * np.cos(theta) * np.sin(theta) * 2 * math.pi * dtheta_du
    assert np.sum(f * wz) * math.pi / 4 == pytest.approx(1.0, abs=2e-6)


@pytest.mark.parametrize("dist", DISTS)
def test_smith_lambda_matches_formula_and_is_continuous(dist):
    c = np.concatenate([np.linspace(1e-3, 0.999999, 2000), [1.0]])
    for m in (1e-4, 0.05, 0.5, 2.0, 10.0):
        got = wenv._smith_lambda(dist, m, c)
        ref = np.array([lambda_ref(dist, m, x) if x < 1 else 0.0 for x in c])
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-14)
        assert np.all(np.isfinite(got)) and np.all(got >= 0)
        assert np.all(np.diff(got) <= 1e-15)  # decreasing towards the normal, no jumps upward
        # Continuity: no step larger than the local slope allows on this grid.
        steps = np.abs(np.diff(got))
        slope = np.abs(np.gradient(got, c))
        assert np.all(steps <= 2 * np.maximum(slope[:-1], slope[1:]) * np.diff(c) + 1e-12)
    # Ends: exactly 0 at the normal, large but finite at the horizon.
    assert wenv._smith_lambda(dist, 0.3, 1.0) == 0.0
    assert np.isfinite(wenv._smith_lambda(dist, 0.3, 0.0)) and wenv._smith_lambda(dist, 0.3, 0.0) > 1e6


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("m", [0.05, 0.3, 1.0])
def test_smith_lambda_weak_white_furnace(dist, m):
    """Smith's masking is exact: Int max(0, wo.h) D(h) d omega_h = (1 + Lambda(wo)) cos(theta_o)."""
    z, wz = np.polynomial.legendre.leggauss(600)
    u = (z + 1) * math.pi / 4
    theta = np.arctan(m * np.tan(u))
    dtheta = m / np.cos(u) ** 2 / (1 + (m * np.tan(u)) ** 2) * wz * math.pi / 4
    phi = (np.arange(720) + 0.5) * 2 * math.pi / 720
    T, P = np.meshgrid(theta, phi, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    D = wenv._ndf(dist, m, np.cos(theta))[:, None]
    for deg in (0, 40, 75, 88):
        wo = unit64(direction(deg))
        proj = np.maximum(h @ wo, 0)
        integral = np.sum(proj * D * np.sin(T) * dtheta[:, None]) * 2 * math.pi / 720
        want = (1 + wenv._smith_lambda(dist, m, wo[2])) * wo[2]
        assert integral == pytest.approx(want, rel=2e-4, abs=1e-6)


# ------------------------------------------------------------------ lobe evaluation

@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("shadow", SHADOWS)
def test_eval_matches_textbook_formulas(dist, shadow):
    rng = np.random.default_rng(1)
    wi, wo = random_upper(rng, 500), random_upper(rng, 500)
    for m, ior in ((0.05, 1.5), (0.4, 2.0), (1.5, 1.2)):
        mat = wenv.CookTorrance(lobes=[{"alpha": m, "ior": ior}], distribution=dist, shadowing=shadow)
        ref = lobe_ref(dist, shadow, m, ior, wi, wo) * unit64(wi)[:, 2]
        got = mat.eval(wi, wo)
        assert got.dtype == np.float32 and got.shape == (500, 3)
        np.testing.assert_allclose(got[:, 0], ref, rtol=2e-5, atol=1e-30)
        np.testing.assert_array_equal(got[:, 0], got[:, 1])


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("shadow", SHADOWS)
def test_reciprocity(dist, shadow):
    rng = np.random.default_rng(2)
    wi, wo = random_upper(rng, 2000), random_upper(rng, 2000)
    mat = wenv.CookTorrance(diffuse=(0.2, 0.1, 0.05), lobes=[{"alpha": 0.2, "ior": 1.6},
                                                             {"alpha": 0.7, "specular": (0.3, 0.5, 0.9)}],
                            distribution=dist, shadowing=shadow)
    f_io = mat.eval(wi, wo) / unit64(wi)[:, 2:3]
    f_oi = mat.eval(wo, wi) / unit64(wo)[:, 2:3]
    np.testing.assert_allclose(f_io, f_oi, rtol=1e-5)


def test_multilobe_is_sum_of_lobes_and_lobe_distribution_overrides():
    rng = np.random.default_rng(3)
    wi, wo = random_upper(rng, 300), random_upper(rng, 300)
    l1 = {"alpha": 0.1, "ior": 1.4, "specular": (1.0, 0.5, 0.25)}
    l2 = {"alpha": 0.5, "ior": 2.0, "specular": 0.5, "distribution": "ggx"}
    both = wenv.CookTorrance(0.3, [l1, l2], distribution="beckmann")
    assert [l["distribution"] for l in both.lobes] == ["beckmann", "ggx"]
    a = wenv.CookTorrance(0.3, [l1])
    b = wenv.CookTorrance(0.0, [dict(l2, distribution="ggx")])
    np.testing.assert_allclose(both.eval(wi, wo), a.eval(wi, wo) + b.eval(wi, wo), rtol=1e-5, atol=1e-7)
    g = wenv.CookTorrance(0.0, [{"alpha": 0.5, "ior": 2.0, "specular": 0.5}], distribution="ggx")
    np.testing.assert_allclose(b.eval(wi, wo), g.eval(wi, wo), rtol=0)


def test_lambert():
    mat = wenv.Lambert((0.2, 0.5, 0.9))
    assert isinstance(mat, wenv.Material)
    assert mat.color == (0.2, 0.5, 0.9)
    rng = np.random.default_rng(4)
    wi, wo = random_upper(rng, 100), random_upper(rng, 100)
    want = np.array([0.2, 0.5, 0.9]) / math.pi * unit64(wi)[:, 2:3]
    np.testing.assert_allclose(mat.eval(wi, wo), want, rtol=1e-6)
    # Directional albedo equals the colour exactly, for every view.
    alb = mat.albedo(np.stack([direction(d) for d in (0, 30, 60, 89.9)]))
    np.testing.assert_array_equal(alb, np.tile([0.2, 0.5, 0.9], (4, 1)))
    assert wenv.Lambert(0.5).color == (0.5, 0.5, 0.5)
    # A CookTorrance without lobes is Lambertian.
    ct = wenv.CookTorrance(diffuse=(0.2, 0.5, 0.9))
    np.testing.assert_array_equal(ct.eval(wi, wo), mat.eval(wi, wo))


def test_eval_shapes_broadcasting_and_normalisation():
    mat = wenv.CookTorrance(0.1, [{"alpha": 0.3}])
    wi = direction(30, 10)
    wo = direction(45, 200)
    single = mat.eval(wi, wo)
    assert single.shape == (3,)
    many = mat.eval(np.tile(wi, (5, 1)), wo)
    assert many.shape == (5, 3)
    np.testing.assert_array_equal(many, np.tile(single, (5, 1)))
    np.testing.assert_allclose(mat.eval(wi * 3, wo * 0.5), single, rtol=1e-6)  # normalised internally
    assert mat.eval(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)).shape == (0, 3)


def test_below_horizon_is_zero():
    mat = wenv.CookTorrance(0.5, [{"alpha": 0.3}])
    up, down, flat = direction(30), direction(120), np.array([0.6, -0.8, 0.0], np.float32)
    for a, b in ((up, down), (down, up), (flat, up), (up, flat), (flat, flat), (down, down)):
        np.testing.assert_array_equal(mat.eval(a, b), 0.0)
    np.testing.assert_array_equal(mat.albedo(down), 0.0)


# ------------------------------------------------------------------ robustness

EDGE_THETAS = [0.0, 1e-7, 1e-3, 30.0, 60.0, 85.0, 89.0, 89.99, 89.9999, 90.0, 95.0, 180.0]


def edge_directions():
    exact = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0.6, 0.8, 0], [0, 0, 1], [0, 0, -1]]  # exact horizon / normal
    d = [direction(t, p) for t in EDGE_THETAS for p in (0.0, 37.0, 90.0, 180.0)]
    return np.concatenate([np.array(exact, np.float32), np.stack(d)])


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("shadow", SHADOWS)
def test_no_nan_or_inf_at_edge_cases(dist, shadow):
    d = edge_directions()
    wi = np.repeat(d, len(d), axis=0)
    wo = np.tile(d, (len(d), 1))
    for m in (1e-6, 1e-4, 0.01, 0.3, 1.0, 10.0):
        for ior in (1.0001, 1.5, 10.0):
            mat = wenv.CookTorrance(1.0, [{"alpha": m, "ior": ior}], distribution=dist, shadowing=shadow)
            v = mat.eval(wi, wo)
            assert np.all(np.isfinite(v)), (m, ior)
            assert np.all(v >= 0)
        a = mat.albedo(d, samples=16)
        assert np.all(np.isfinite(a)) and np.all(a >= 0)
        s = wenv._smith_lambda(dist, m, np.array([0.0, 1e-300, 1e-12, 0.5, 1.0]))
        assert np.all(np.isfinite(s))
        D = wenv._ndf(dist, m, np.array([0.0, 1e-300, 1e-160, 1e-8, 0.5, 1.0]))
        assert np.all(np.isfinite(D))


def test_exact_normal_incidence_and_mirror_configuration():
    n = np.array([0, 0, 1], np.float32)
    for dist in DISTS:
        mat = wenv.CookTorrance(lobes=[{"alpha": 1e-4, "ior": 1.5}], distribution=dist)
        v = mat.eval(n, n)[0]
        # D(n) = 1/(pi m^2), G = 1, F = 0.04: f cos = 0.04 / (4 pi m^2)
        assert v == pytest.approx(0.04 / (4 * math.pi * 1e-8), rel=1e-5)


# ------------------------------------------------------------------ albedo and energy

WHITE_ROUGHNESS = [0.01, 0.05, 0.1, 0.2, 0.5, 1.0]
VIEWS = [0, 15, 30, 45, 60, 75, 85, 89]


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("shadow", SHADOWS)
def test_white_furnace_microfacet_part(dist, shadow):
    """With F = 1, Int D G / (4 ci co) ci d wi <= 1: the microfacet part creates no energy."""
    for m in WHITE_ROUGHNESS:
        for deg in VIEWS:
            a = wenv._lobe_albedo(direction(deg), m, dist, shadow, fresnel=False)
            assert 0.0 < a <= 1.0 + 1e-3, (m, deg, a)
    # Smooth surfaces seen from above lose nothing: the D normalisation and G are right.
    assert wenv._lobe_albedo(direction(0), 0.01, "beckmann", shadow, fresnel=False) == pytest.approx(1, abs=1e-6)
    assert wenv._lobe_albedo(direction(30), 0.01, dist, "smith", fresnel=False) == pytest.approx(1, abs=1e-3)


@pytest.mark.parametrize("shadow", SHADOWS)
def test_white_material_albedo_below_one(shadow):
    views = np.stack([direction(d) for d in VIEWS])
    for dist in DISTS:
        for m in WHITE_ROUGHNESS:
            mat = wenv.CookTorrance(0.0, [{"specular": (1, 1, 1), "alpha": m, "ior": 10.0}], dist, shadow)
            a = mat.albedo(views)
            assert a.dtype == np.float64 and a.shape == (len(VIEWS), 3)
            assert np.all(a <= 1 + 1e-3) and np.all(a > 0)


def test_albedo_quadrature_converged():
    for dist in DISTS:
        for shadow in SHADOWS:
            for m in (0.01, 0.1, 1.0):
                for deg in (0, 60, 89):
                    w = direction(deg)
                    a = wenv._lobe_albedo(w, m, dist, shadow, fresnel=True, ior=1.5)
                    ref = wenv._lobe_albedo(w, m, dist, shadow, fresnel=True, ior=1.5, samples=768)
                    assert a == pytest.approx(ref, abs=1e-4), (dist, shadow, m, deg)


def test_albedo_agrees_with_brute_force_over_incident_directions():
    """Half-vector quadrature vs. a plain product rule over wi (cos_i, phi) on eval()."""
    z, wz = np.polynomial.legendre.leggauss(300)
    mu = (z + 1) / 2
    phi = (np.arange(600) + 0.5) * 2 * math.pi / 600
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - M**2)
    wi = np.stack([s * np.cos(P), s * np.sin(P), M], -1).reshape(-1, 3).astype(np.float32)
    weights = (np.outer(wz / 2, np.full(600, 2 * math.pi / 600))).reshape(-1)
    mat = wenv.CookTorrance((0.1, 0.2, 0.3), [{"alpha": 0.4, "ior": 1.5, "specular": (1, 0.5, 0.25)},
                                               {"alpha": 0.8, "ior": 3.0, "distribution": "ggx"}])
    for deg in (0, 50, 80):
        wo = direction(deg, 20)
        # eval() already includes cos_i, and d omega = d mu d phi
        brute = (mat.eval(wi, wo).astype(np.float64) * weights[:, None]).sum(0)
        np.testing.assert_allclose(mat.albedo(wo), brute, atol=1e-3)


# ------------------------------------------------------------------ batch path

def test_batch_equals_scalar_path():
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(1000, 3)).astype(np.float32)  # includes directions below the horizon
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi[:10] = edge_directions()[:10]
    for shadow in SHADOWS:
        mat = wenv.CookTorrance(0.5, [{"alpha": 0.05, "ior": 1.5, "specular": 0.4}, {"alpha": 0.3, "distribution": "ggx",
                                                                        "specular": (0.2, 0.4, 0.6)},
                                      {"alpha": 2.0, "ior": 4.0, "specular": 0.1}], shadowing=shadow)
        for deg in (0, 30, 70, 89.9, 90, 120):
            wo = direction(deg, 33)
            batch = wenv._specular_batch(mat, wi, wo)
            scalar = wenv._specular(mat, wi, wo)
            np.testing.assert_allclose(batch, scalar, rtol=1e-12, atol=0)
            # eval = specular + diffuse/pi cos_i (above the horizon)
            if deg < 90:
                diff = np.where(wi[:, 2:3] > 0, 0.5 / math.pi * wi[:, 2:3], 0)
                np.testing.assert_allclose(mat.eval(wi, wo), scalar + diff, rtol=1e-6, atol=1e-7)


# ------------------------------------------------------------------ Python object behaviour

def test_attributes_repr_pickle_and_immutability():
    ct = wenv.CookTorrance(diffuse=(0.1, 0.2, 0.3), lobes=[{"alpha": 0.2}], distribution="ggx",
                           shadowing="vcavity")
    assert isinstance(ct, wenv.Material) and isinstance(wenv.Lambert(0.1), wenv.Material)
    assert ct.diffuse == (0.1, 0.2, 0.3)
    assert ct.lobes == [{"specular": (1.0, 1.0, 1.0), "alpha": 0.2, "ior": 1.5, "distribution": "ggx"}]
    assert ct.distribution == "ggx" and ct.shadowing == "vcavity"
    assert "CookTorrance" in repr(ct) and "vcavity" in repr(ct)
    assert eval(repr(ct), {"wenv": wenv}) == ct
    assert pickle.loads(pickle.dumps(ct)) == ct
    lam = wenv.Lambert((0.1, 0.2, 0.3))
    assert pickle.loads(pickle.dumps(lam)) == lam and hash(lam) == hash(wenv.Lambert((0.1, 0.2, 0.3)))
    assert lam != wenv.CookTorrance((0.1, 0.2, 0.3))
    for obj, attr in ((ct, "diffuse"), (ct, "lobes"), (ct, "distribution"), (ct, "shadowing"), (lam, "color")):
        with pytest.raises(AttributeError):
            setattr(obj, attr, 0)
    ct.lobes[0]["alpha"] = 5.0  # a copy: the material does not change
    assert ct.lobes[0]["alpha"] == 0.2
    with pytest.raises(TypeError):
        wenv.Material()


def test_with_alpha():
    ct = wenv.CookTorrance(0.1, [{"alpha": 0.2, "ior": 1.7}, {"alpha": 0.5, "distribution": "ggx"}],
                           shadowing="vcavity")
    r = ct.with_alpha(0.05)
    assert [l["alpha"] for l in r.lobes] == [0.05, 0.05]
    assert [l["ior"] for l in r.lobes] == [1.7, 1.5] and r.shadowing == "vcavity"
    assert ct.lobes[0]["alpha"] == 0.2
    with pytest.raises(ValueError, match="alpha"):
        ct.with_alpha(0.0)
    with pytest.raises(ValueError, match="alpha"):
        ct.with_alpha(float("nan"))


def test_roughness_is_blenders_everywhere():
    """`roughness` is Blender's perceptual r wherever a user meets it; a lobe's parameter is alpha.
    The names that meant alpha fail with an error that names what replaced them."""
    with pytest.raises(ValueError, match=r"lobes\[0\]: a lobe takes 'alpha'.*alpha_from_roughness"):
        wenv.CookTorrance(lobes=[{"roughness": 0.2}])
    ct = wenv.CookTorrance(lobes=[{"alpha": 0.2}])
    with pytest.raises(TypeError, match=r"with_alpha\(alpha\)"):
        ct.with_roughness(0.2)
    with pytest.raises(AttributeError, match="ALPHA_RANGE"):
        wenv.ROUGHNESS_RANGE
    with pytest.raises(AttributeError, match="no attribute 'NO_SUCH_NAME'"):
        wenv.NO_SUCH_NAME
    # the one conversion takes a Principled roughness to the lobe's alpha
    paint = wenv.Principled(roughness=0.3, base_color=0.0, specular_ior_level=0.0, metallic=1.0)
    assert paint.inputs["roughness"] == 0.3
    assert wenv.alpha_from_roughness(0.3) == pytest.approx(0.09)


# ------------------------------------------------------------------ argument validation

def ct(**kw):
    args = dict(diffuse=0.1, lobes=[{"alpha": 0.2}])
    args.update(kw)
    return wenv.CookTorrance(**args)


def lobe(**kw):
    d = {"alpha": 0.2, "ior": 1.5, "specular": 1.0}
    d.update(kw)
    return d


BAD = [
    # (callable, exception, text the message must contain)
    (lambda: wenv.Lambert(1.2), ValueError, "color"),
    (lambda: wenv.Lambert((0.5, 1.01, 0.5)), ValueError, "color"),
    (lambda: wenv.Lambert(-0.1), ValueError, "color"),
    (lambda: wenv.Lambert((0.5, 0.5)), ValueError, "color"),
    (lambda: wenv.Lambert(float("nan")), ValueError, "color"),
    (lambda: wenv.Lambert("red"), TypeError, "color"),
    (lambda: ct(diffuse=1.5), ValueError, "diffuse"),
    (lambda: ct(diffuse=(0.1, -0.1, 0.1)), ValueError, "diffuse"),
    (lambda: ct(diffuse=None), TypeError, "diffuse"),
    (lambda: ct(lobes=5), TypeError, "lobes"),
    (lambda: ct(lobes={"alpha": 0.2}), TypeError, "lobes"),
    (lambda: ct(lobes=[lobe(), 3]), TypeError, "lobes[1]"),
    (lambda: ct(lobes=[lobe(gloss=1)]), ValueError, "gloss"),
    (lambda: ct(lobes=[lobe(), {"specular": 1.0}]), ValueError, "lobes[1].alpha"),
    (lambda: ct(lobes=[lobe(alpha=0.0)]), ValueError, "lobes[0].alpha"),
    (lambda: ct(lobes=[lobe(), lobe(alpha=-1.0)]), ValueError, "lobes[1].alpha"),
    (lambda: ct(lobes=[lobe(alpha=10.5)]), ValueError, "lobes[0].alpha"),
    (lambda: ct(lobes=[lobe(alpha=float("inf"))]), ValueError, "lobes[0].alpha"),
    (lambda: ct(lobes=[lobe(alpha=float("nan"))]), ValueError, "lobes[0].alpha"),
    (lambda: ct(lobes=[lobe(alpha="rough")]), TypeError, "lobes[0].alpha"),
    (lambda: ct(lobes=[lobe(ior=1.0)]), ValueError, "lobes[0].ior"),
    (lambda: ct(lobes=[lobe(ior=0.5)]), ValueError, "lobes[0].ior"),
    (lambda: ct(lobes=[lobe(), lobe(ior=10.01)]), ValueError, "lobes[1].ior"),
    (lambda: ct(lobes=[lobe(ior=float("nan"))]), ValueError, "lobes[0].ior"),
    (lambda: ct(lobes=[lobe(specular=-0.5)]), ValueError, "lobes[0].specular"),
    (lambda: ct(lobes=[lobe(specular=(1, 1))]), ValueError, "lobes[0].specular"),
    (lambda: ct(lobes=[lobe(), lobe(specular=(1, float("inf"), 1))]), ValueError, "lobes[1].specular"),
    (lambda: ct(lobes=[lobe(distribution="phong")]), ValueError, "lobes[0].distribution"),
    (lambda: ct(lobes=[lobe(distribution=1)]), TypeError, "lobes[0].distribution"),
    (lambda: ct(distribution="blinn"), ValueError, "distribution"),
    (lambda: ct(distribution=None), TypeError, "distribution"),
    (lambda: ct(shadowing="none"), ValueError, "shadowing"),
    (lambda: ct(shadowing=0), TypeError, "shadowing"),
]


@pytest.mark.parametrize("i", range(len(BAD)))
def test_bad_constructor_arguments(i):
    fn, exc, text = BAD[i]
    with pytest.raises(exc) as info:
        fn()
    assert text in str(info.value)


def test_bad_eval_and_albedo_arguments():
    mat = ct()
    good = direction(10)
    cases = [
        (lambda: mat.eval(good.astype(np.float64), good), TypeError, "wi"),
        (lambda: mat.eval(good, [0, 0, 1]), TypeError, "wo"),
        (lambda: mat.eval(np.zeros((2, 4), np.float32), good), ValueError, "wi"),
        (lambda: mat.eval(good, np.array([0, 0, np.nan], np.float32)), ValueError, "wo"),
        (lambda: mat.eval(np.zeros(3, np.float32), good), ValueError, "wi"),
        (lambda: mat.eval(np.tile(good, (2, 1)), np.tile(good, (3, 1))), ValueError, "wi and wo"),
        (lambda: mat.albedo(good, samples=4), ValueError, "samples"),
        (lambda: mat.albedo(good, samples=10**9), ValueError, "samples"),
        (lambda: mat.albedo(good, samples=-1), ValueError, "samples"),
        (lambda: mat.albedo(good, samples=64.0), TypeError, "samples"),
        (lambda: mat.albedo(np.ones((2, 2), np.float32)), ValueError, "wo"),
        (lambda: wenv._ndf("beckmann", 0.0, 0.5), ValueError, "alpha"),
        (lambda: wenv._fresnel(0.5, 1.0), ValueError, "ior"),
    ]
    for fn, exc, text in cases:
        with pytest.raises(exc) as info:
            fn()
        assert text in str(info.value)


def test_one_roughness_range_and_conversion():
    """The accepted range and Blender's roughness conversion come from the core, once."""
    lo, hi = wenv.ALPHA_RANGE
    wenv.CookTorrance(lobes=[{"alpha": lo}, {"alpha": hi}])
    for bad in (lo * 0.999, hi * 1.001):
        with pytest.raises(ValueError, match="alpha"):
            wenv.CookTorrance(lobes=[{"alpha": bad}])
    ior_lo, ior_hi = wenv.IOR_RANGE
    wenv.CookTorrance(lobes=[{"alpha": 0.1, "ior": ior_hi}])
    with pytest.raises(ValueError, match="ior"):
        wenv.CookTorrance(lobes=[{"alpha": 0.1, "ior": ior_lo}])
    assert wenv.alpha_from_roughness(0.5) == 0.25
    assert wenv.alpha_from_roughness(0.0) == 1e-4          # a mirror keeps a lobe
    assert lo <= wenv.alpha_from_roughness(0.0) and wenv.alpha_from_roughness(1.0) <= hi
    with pytest.raises(ValueError, match="roughness"):
        wenv.alpha_from_roughness(float("nan"))
    with pytest.raises(ValueError, match="roughness"):
        wenv.alpha_from_roughness(-0.1)


def test_lobes_that_reflect_more_than_they_receive_are_refused():
    # what the material's own albedo says, independently of the check: five white lobes pass 1 at 75 degrees
    one = wenv.CookTorrance(0.0, [{"specular": 1, "alpha": 0.1, "ior": 1.5}])
    assert 5 * one.albedo(direction(75))[0] > 1.1
    with pytest.raises(ValueError, match="lobes reflect .* times the light they receive .* 75 degrees"):
        wenv.CookTorrance(0.0, [{"specular": 1, "alpha": 0.1, "ior": 1.5}] * 5)
    # towards grazing lobes added rather than layered pass 1 (a coat over a paint's gloss): accepted
    two = wenv.CookTorrance(0.0, [{"specular": 1, "alpha": 0.1, "ior": 1.5}] * 2)
    assert two.albedo(direction(89))[0] > 1.05
    with pytest.raises(ValueError, match="blue channel"):
        wenv.CookTorrance(0.0, [{"specular": (0.2, 0.2, 30.0), "alpha": 0.3, "ior": 1.5}])
    # a hundred white lobes reflected 4.4 times a unit environment
    with pytest.raises(ValueError, match="lobes: at most 64, got 100"):
        wenv.CookTorrance(0.0, [{"specular": 1, "alpha": 0.1, "ior": 1.5}] * 100)
    # lobes that share an albedo of at most 1 are accepted, up to the limit, and so is each white lobe alone
    half = wenv.CookTorrance(0.0, [{"specular": 0.5, "alpha": m, "ior": 1.5} for m in (0.1, 0.3)])
    assert np.all(half.albedo(np.stack([direction(d) for d in (0, 60, 89)])) <= 1.0)
    wenv.CookTorrance(0.0, [{"specular": 0.01, "alpha": 0.05 + 0.01 * i, "ior": 1.5} for i in range(64)])
    for dist in DISTS:
        for shadow in SHADOWS:
            for m in (0.001, 0.05, 1.0):
                wenv.CookTorrance(0.0, [{"specular": 1, "alpha": m, "ior": 10.0}], dist, shadow)


# ------------------------------------------------------------------ symmetry the wavelet shader relies on

# The square's eight symmetries of the hemi-octahedral grids, as maps of (x, y) about the normal:
# brdf_slices.c integrates one BRDF slice per orbit of the view samples and permutes it for the rest
# for every kind whose `mirror_symmetric` flag is set (Lambert, Cook-Torrance, Principled).
SQUARE_SYMMETRIES = [np.array(m, np.float32) for m in (
    [[1, 0], [0, 1]], [[0, 1], [1, 0]], [[0, -1], [-1, 0]], [[-1, 0], [0, -1]],
    [[1, 0], [0, -1]], [[-1, 0], [0, 1]], [[0, 1], [-1, 0]], [[0, -1], [1, 0]])]


def turned(v, m):
    out = v.copy()
    out[:, :2] = v[:, :2] @ m.T
    return out


@pytest.mark.parametrize("name", ["lambert", "cook_torrance", "principled", "principled_anisotropic"])
def test_kinds_flagged_mirror_symmetric_are(name):
    """f(M wi, M wo) = f(wi, wo) for each symmetry M: what sharing slices across an orbit assumes.
    Principled's anisotropy is unhonoured today; honouring it must clear the kind's flag, and this
    test then fails for the anisotropic material."""
    mat = {
        "lambert": lambda: wenv.Lambert((0.6, 0.3, 0.2)),
        "cook_torrance": lambda: wenv.CookTorrance(0.2, [{"alpha": 0.15, "ior": 1.5, "specular": 1.0},
                                                         {"alpha": 0.5, "ior": 1.8, "specular": 0.4,
                                                          "distribution": "ggx"}]),
        "principled": lambda: wenv.Principled(base_color=(0.8, 0.5, 0.2), metallic=0.3, roughness=0.35,
                                              coat_weight=0.7, coat_roughness=0.1, sheen_weight=0.5),
        "principled_anisotropic": lambda: wenv.Principled(base_color=(0.8, 0.5, 0.2), roughness=0.35,
                                                          anisotropic=0.8, anisotropic_rotation=0.1),
    }[name]
    if name == "principled_anisotropic":
        with pytest.warns(UserWarning, match="anisotropic"):
            mat = mat()
    else:
        mat = mat()
    rng = np.random.default_rng(5)
    wi, wo = random_upper(rng, 500), random_upper(rng, 500)
    base = mat.eval(wi, wo)
    assert np.all(base > 0)
    for m in SQUARE_SYMMETRIES[1:]:
        np.testing.assert_allclose(mat.eval(turned(wi, m), turned(wo, m)), base, rtol=2e-5, atol=1e-9)


def test_mirror_symmetry_check_can_fail():
    """A table whose phi_d half is brighter than its mirror is not mirror symmetric (its kind's flag is
    clear): the property above is not a tautology of the evaluation."""
    table = np.full((16, 16, 32, 3), 0.05, np.float64)
    table[:, :, 4:12] = 0.3
    mat = wenv.Tabulated(table)
    rng = np.random.default_rng(6)
    wi, wo = random_upper(rng, 500), random_upper(rng, 500)
    mirrored = mat.eval(turned(wi, SQUARE_SYMMETRIES[4]), turned(wo, SQUARE_SYMMETRIES[4]))
    assert np.max(np.abs(mirrored - mat.eval(wi, wo))) > 0.1


# ------------------------------------------------------------------ narrow lobes' BRDF slices

def smooth_environment():
    """A sky of a few low-frequency waves, no bright pixel: what a lobe reflects comes from the slices."""
    th = (np.arange(64) + 0.5) / 64 * np.pi
    ph = np.arange(128) / 128 * 2 * np.pi
    t, p = np.meshgrid(th, ph, indexing="ij")
    img = 1.0 + 0.6 * np.cos(3 * t) * np.sin(2 * p) + 0.4 * np.sin(5 * p + t)
    return wenv.Environment(np.ascontiguousarray(np.stack([img, 0.8 * img ** 2, 1.2 + 0.5 * np.cos(4 * t)], -1),
                                                 np.float32))


# relative RMSE with the fine rule read on every texel (the build before it was read only near the
# lobe: the same to 0.001 %), x 1.05.  Read on no texel, these lobes err by 78-100 %.
NARROW_BOUNDS = {(0.005, "beckmann"): 0.0656, (0.005, "ggx"): 0.0627, (0.02, "beckmann"): 0.0543,
                 (0.02, "ggx"): 0.0469}


@pytest.mark.parametrize("m,dist", sorted(NARROW_BOUNDS))
def test_narrow_lobe_slices_take_the_fine_rule_about_the_mirror_direction(m, dist):
    """A lobe narrower than the 2 x 2 sub-samples per texel resolve (m < 0.028 at 64^2 local maps)
    is integrated on a finer rule only near its mirror direction (brdf_slices.c): the shading,
    through the slices alone (no grazing path, no lights), errs against the reference as it did with
    the fine rule everywhere -- GGX's long tails included."""
    from conftest import random_pairs
    env = smooth_environment()
    mat = wenv.CookTorrance(diffuse=0.0, lobes=[{"alpha": m, "ior": 1.5}], distribution=dist)
    nrm, v = random_pairs(400, seed=3)
    keep = np.sum(nrm * v, axis=1) > 0.5
    nrm, v = nrm[keep], v[keep]
    ref = wenv.reference(env, mat, nrm, v)
    out = wenv.Shader(env, mat, quality={"grazing": 0}, method="slicing").shade(nrm, v)
    err = np.sqrt(np.mean((out - ref) ** 2) / np.mean(ref ** 2))
    assert err <= NARROW_BOUNDS[(m, dist)], err
