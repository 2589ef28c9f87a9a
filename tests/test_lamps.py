"""The scene's lamps (wenv.Lamp) in Cycles' units: closed forms of their irradiance, every method's lamp
light against the reference that sums each lamp over a fine grid of its surface, shadows against
the reference's own rays, each vertex's own material and colour, the World's strength and turn
leaving lamps alone, a lamp's own blockers (shadow linking), a new power making nothing again, and bad
input.  Against Cycles itself:
tests/test_lamps_cycles.py."""
import math

import numpy as np
import pytest

import wenv
from tests.helpers.meshes import uv_sphere
from tests.test_shadows import sphere_on_plane

BLACK = wenv.Environment(np.zeros((16, 32, 3), np.float32))


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((np.float64(a) - b) ** 2)) / np.sqrt(np.mean(np.float64(b) ** 2)))


def placed(location, shine=None, scale=(1.0, 1.0, 1.0)):
    """A 4 x 4 matrix_world at `location` whose -Z points along `shine` (None: down)."""
    m = np.eye(4)
    if shine is not None:
        z = -np.asarray(shine, float) / np.linalg.norm(shine)
        x = np.cross([0.0, 0.0, 1.0], z) if abs(z[2]) < 0.9 else np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        m[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
    m[:3, :3] = m[:3, :3] @ np.diag(scale)
    m[:3, 3] = location
    return m


def floor(half=2.0, count=9):
    """Points of the plane z = 0 facing up, seen from straight above."""
    g = np.linspace(-half, half, count)
    p = np.array([[x, y, 0.0] for x in g for y in g], np.float32)
    up = np.tile(np.float32([0, 0, 1]), (len(p), 1))
    return p, up, up.copy()


# ---- closed forms: what a Lambertian floor receives ----

def shade_floor(lamp, albedo=0.8):
    p, n, v = floor()
    shader = wenv.Shader(BLACK, wenv.Lambert(albedo), quality="draft")
    return p, shader.shade(n, v, positions=p, lamps=[lamp])[:, 0] * math.pi / albedo  # the irradiance


def test_a_point_lamp_falls_off_as_the_inverse_square():
    """Radius 0: intensity P / (4 pi); a sphere of any radius (Soft Falloff off) lights as its centre."""
    for kw in ({}, {"radius": 0.5, "soft_falloff": False}):
        p, e = shade_floor(wenv.Lamp("POINT", placed((0.3, -0.2, 2.0)), energy=100.0, **kw))
        d2 = (p[:, 0] - 0.3) ** 2 + (p[:, 1] + 0.2) ** 2 + 4.0
        expected = 100.0 / (4 * math.pi) * (2.0 / np.sqrt(d2)) / d2
        assert np.allclose(e, expected, rtol=2e-4), kw


def test_soft_falloff_is_a_disk_facing_the_point():
    """On the axis a facing disk of radius r gives P / (4 pi (d^2 + r^2)) (Cycles' soft falloff)."""
    p, e = shade_floor(wenv.Lamp("POINT", placed((0.0, 0.0, 1.5)), energy=100.0, radius=0.6))
    centre = np.flatnonzero((p[:, 0] == 0) & (p[:, 1] == 0))[0]
    assert e[centre] == pytest.approx(100.0 / (4 * math.pi * (1.5 ** 2 + 0.6 ** 2)), rel=2e-4)


def test_a_sun_gives_its_strength_head_on():
    for angle in (0.0, 0.4):
        _, e = shade_floor(wenv.Lamp("SUN", placed((0, 0, 5)), energy=3.0, angle=angle))
        assert np.allclose(e, 3.0, rtol=2e-4), angle
        _, tilted = shade_floor(wenv.Lamp("SUN", placed((0, 0, 5), shine=(1.0, 0.0, -1.0)), energy=3.0, angle=angle))
        assert np.allclose(tilted, 3.0 * math.cos(math.pi / 4), rtol=2e-4), angle


def rectangle_psa_from_corner(a, b, h):
    """The projected solid angle of an a x b rectangle parallel to the floor at height h, seen from
    below one corner: pi times the form factor's closed form."""
    x, y = a / h, b / h
    return 0.5 * (x / math.hypot(1, x) * math.atan(y / math.hypot(1, x)) +
                  y / math.hypot(1, y) * math.atan(x / math.hypot(1, y)))


def test_an_area_lamp_lights_as_its_closed_form():
    """Under the centre of a 1.2 x 0.8 lamp 1.5 above: four corner rectangles; power P over pi A is
    its radiance.  A disk's on its axis is pi r^2 / (r^2 + h^2).  Nothing behind it."""
    lamp = wenv.Lamp("AREA", placed((0, 0, 1.5)), energy=50.0, shape="RECTANGLE", size=1.2, size_y=0.8)
    p, e = shade_floor(lamp)
    centre = np.flatnonzero((p[:, 0] == 0) & (p[:, 1] == 0))[0]
    radiance = 50.0 / (math.pi * 1.2 * 0.8)
    assert e[centre] == pytest.approx(radiance * 4 * rectangle_psa_from_corner(0.6, 0.4, 1.5), rel=1e-4)
    disk = wenv.Lamp("AREA", placed((0, 0, 1.5)), energy=50.0, shape="DISK", size=1.0)
    _, e = shade_floor(disk)
    assert e[centre] == pytest.approx(50.0 / (math.pi * math.pi * 0.25) * math.pi * 0.25 / (0.25 + 2.25), rel=1e-3)
    _, behind = shade_floor(wenv.Lamp("AREA", placed((0, 0, 1.5), shine=(0, 0, 1)), energy=50.0))
    assert not behind.any()


def test_a_spot_cone_and_blend():
    """Inside the cone as a point lamp; outside nothing; the blend a smoothstep in cos."""
    spot = wenv.Lamp("SPOT", placed((0, 0, 2.0)), energy=100.0, spot_size=math.radians(60), spot_blend=0.0)
    p, e = shade_floor(spot)
    d2 = p[:, 0] ** 2 + p[:, 1] ** 2 + 4.0
    cos = 2.0 / np.sqrt(d2)
    inside = cos > math.cos(math.radians(30))
    assert np.allclose(e[inside], (100.0 / (4 * math.pi) * cos / d2)[inside], rtol=2e-4)
    assert not e[~inside].any()
    blend = wenv.Lamp("SPOT", placed((0, 0, 2.0)), energy=100.0, spot_size=math.radians(60), spot_blend=1.0)
    _, eb = shade_floor(blend)
    x = np.clip((cos - math.cos(math.radians(30))) / (1 - math.cos(math.radians(30))), 0, 1)
    assert np.allclose(eb, 100.0 / (4 * math.pi) * cos / d2 * x * x * (3 - 2 * x), rtol=2e-4, atol=1e-7)


def test_units_follow_cycles_switches():
    """Exposure doubles per stop; normalize off drops the 1 / area (radiance P / pi); colour scales
    each channel; a lamp invisible to diffuse rays lights no Lambertian part."""
    base = wenv.Lamp("AREA", placed((0, 0, 1)), energy=10.0, size=0.5)
    assert wenv.Lamp("AREA", placed((0, 0, 1)), energy=10.0, size=0.5, exposure=2.0).radiance[0] == pytest.approx(
        4 * base.radiance[0])
    assert base.radiance[0] == pytest.approx(10.0 / (math.pi * 0.25))
    raw = wenv.Lamp("AREA", placed((0, 0, 1)), energy=10.0, size=0.5, normalize=False)
    assert raw.radiance[0] == pytest.approx(10.0 / math.pi)
    assert wenv.Lamp("POINT", energy=10.0, color=(1.0, 0.5, 0.0)).radiance == pytest.approx(
        (10 / (4 * math.pi), 5 / (4 * math.pi), 0.0))
    _, e = shade_floor(wenv.Lamp("AREA", placed((0, 0, 1)), energy=10.0, diffuse=False))
    assert not e.any()


# ---- every method against the reference ----

def lit_sphere(n=120, seed=1):
    rng = np.random.default_rng(seed)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    eye = np.array([0.3, -4.0, 2.5])
    views = eye - nrm
    return np.float32(nrm), np.float32(nrm), np.float32(views)


LAMPS = {
    "sun": lambda: wenv.Lamp("SUN", placed((0, 0, 0), shine=(-0.3, 0.5, -1.0)), energy=3.0, angle=0.2),
    "point": lambda: wenv.Lamp("POINT", placed((1.5, -1.5, 2.0)), energy=300.0, radius=0.3),
    "sphere": lambda: wenv.Lamp("POINT", placed((1.5, -1.5, 2.0)), energy=300.0, radius=0.5, soft_falloff=False),
    "spot": lambda: wenv.Lamp("SPOT", placed((0, -2, 2), shine=(0, 1, -1)), energy=500.0, radius=0.2,
                              spot_size=1.2, spot_blend=0.3),
    "area": lambda: wenv.Lamp("AREA", placed((0, -2, 1.5), shine=(0, 1, -0.7)), energy=200.0, size=1.5),
    "ellipse, spread": lambda: wenv.Lamp("AREA", placed((-1, -1, 2), shine=(0.5, 0.5, -1.0)), energy=200.0,
                                         shape="ELLIPSE", size=1.5, size_y=0.6, spread=1.2),
}
MATERIALS = {
    "lambert": lambda: wenv.Lambert(0.7),
    "paint": lambda: wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4),
    "metal": lambda: wenv.Principled(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.2),
}


@pytest.mark.parametrize("material", list(MATERIALS))
def test_lamps_match_the_reference(material):
    """Each lamp alone on a sphere of normals seen from one eye: within 1 % of the reference."""
    positions, normals, views = lit_sphere()
    mat = MATERIALS[material]()
    shader = wenv.Shader(BLACK, mat, quality="draft")
    for name, make in LAMPS.items():
        lamp = make()
        fast = shader.shade(normals, views, positions=positions, lamps=[lamp])
        ref = wenv.reference(BLACK, mat, normals, views, positions=positions, lamps=[lamp])
        assert ref.mean() > 1e-3, name
        assert relative_rmse(fast, ref) < 0.01, (name, relative_rmse(fast, ref))


def test_every_method_adds_the_same_lamp_light():
    """Lamps are shaded apart from the environment's methods: under a black World each gives the
    same, and with a World each adds them to its own shading."""
    positions, normals, views = lit_sphere(60)
    mat = MATERIALS["paint"]()
    lamps = [LAMPS["area"](), LAMPS["sun"]()]
    results = [wenv.Shader(BLACK, mat, method=m, quality="draft").shade(normals, views, positions=positions,
                                                                       lamps=lamps)
               for m in ("rotation", "slicing", "split_sum", "sh")]
    for r in results[1:]:
        assert np.allclose(r, results[0], rtol=1e-5, atol=1e-7)
    sky = wenv.Environment(np.full((16, 32, 3), 0.2, np.float32))
    shader = wenv.Shader(sky, mat, method="split_sum", quality="draft")
    alone = shader.shade(normals, views)
    assert np.allclose(shader.shade(normals, views, positions=positions, lamps=lamps), alone + results[0],
                       rtol=1e-4, atol=1e-6)


def test_the_world_strength_and_turn_leave_lamps_alone():
    positions, normals, views = lit_sphere(60)
    mat = MATERIALS["paint"]()
    lamps = [LAMPS["point"]()]
    sky = np.full((16, 32, 3), 0.3, np.float32)
    sky[:8, :4] = 3.0
    plain = wenv.Environment(sky)
    turned = plain.with_transform(rotation=0.7, strength=2.5)
    for env in (plain, turned):
        shader = wenv.Shader(env, mat, quality="draft")
        lamp_part = shader.shade(normals, views, positions=positions, lamps=lamps) - shader.shade(normals, views)
        black = wenv.Shader(BLACK, mat, quality="draft").shade(normals, views, positions=positions, lamps=lamps)
        assert np.allclose(lamp_part, black, rtol=1e-4, atol=1e-6)


def test_each_vertex_own_material_and_colour():
    """Roughness, Metallic and Base Color per vertex light each vertex with its own material, as the
    reference shades each with its own, within 1.5 %."""
    positions, normals, views = lit_sphere(150, seed=4)
    rng = np.random.default_rng(5)
    roughness = np.float32(rng.uniform(0.2, 0.8, len(normals)))
    metallic = np.float32(rng.integers(0, 2, len(normals)))
    colour = np.float32(rng.uniform(0.1, 0.9, (len(normals), 3)))
    mat = wenv.Principled(base_color=(0.5, 0.5, 0.5), roughness=0.5)
    lamps = [LAMPS["area"](), LAMPS["point"]()]
    shader = wenv.Shader(BLACK, mat, quality="draft")
    fast = shader.shade(normals, views, positions=positions, lamps=lamps, roughness=roughness, metallic=metallic,
                        base_color=colour)
    ref = wenv.reference(BLACK, mat, normals, views, positions=positions, lamps=lamps, roughness=roughness,
                         metallic=metallic, base_color=colour)
    assert relative_rmse(fast, ref) < 0.015, relative_rmse(fast, ref)


# ---- shadows ----

@pytest.fixture(scope="module")
def contact():
    positions, triangles, normals = sphere_on_plane()
    occluders = wenv.Occluders(positions, triangles)
    views = np.float32([4, -5, 4]) - positions
    return positions, normals, views, occluders, occluders.occlusion(positions, normals)


@pytest.mark.parametrize("lamp, bound", [("sun", 0.01), ("point", 0.015), ("area", 0.03)])
def test_lamp_shadows_match_the_reference_rays(contact, lamp, bound):
    """A sphere resting on a plane: the fast path's rays (4 x 4 cells of a wide lamp) against the
    reference's ray per point of its grid.  Soft shadows of a wide lamp within 3 %."""
    positions, normals, views, occluders, occlusion = contact
    make = {"sun": lambda: wenv.Lamp("SUN", placed((0, 0, 0), shine=(0.5, 0.3, -1.0)), energy=3.0, angle=0.1),
            "point": lambda: wenv.Lamp("POINT", placed((1.5, -1.0, 2.5)), energy=300.0, radius=0.3),
            "area": lambda: wenv.Lamp("AREA", placed((-1, 1, 3), shine=(0.3, -0.3, -1.0)), energy=400.0,
                                      size=1.2)}[lamp]
    mat = wenv.Principled(base_color=(0.8, 0.3, 0.2), roughness=0.3)
    shader = wenv.Shader(BLACK, mat, quality="draft")
    fast = shader.shade(normals, views, occlusion=occlusion, bounce=None, positions=positions, lamps=[make()])
    ref = wenv.reference(BLACK, mat, normals, views, positions=positions, occluders=occluders, lamps=[make()])
    unshadowed = wenv.reference(BLACK, mat, normals, views, positions=positions, lamps=[make()])
    assert relative_rmse(unshadowed, ref) > 0.15  # the shadows matter here
    assert relative_rmse(fast, ref) < bound, relative_rmse(fast, ref)
    # a lamp that casts no shadow lights through the sphere
    free = shader.shade(normals, views, occlusion=occlusion, bounce=None, positions=positions,
                        lamps=[wenv.Lamp("SUN", placed((0, 0, 0), shine=(0.5, 0.3, -1.0)), energy=3.0, angle=0.1,
                                         cast_shadow=False)])
    if lamp == "sun":
        assert relative_rmse(free, unshadowed) < 0.01


def test_a_lamps_own_blockers_stand_for_the_scenes(contact):
    """Shadow linking: a lamp given blockers is blocked by them alone where the call is shadowed, in
    the fast path and the reference alike; given the scene's own occluders, it is shaded as without."""
    positions, normals, views, occluders, occlusion = contact
    sphere_triangles = len(uv_sphere(16, 32, 1.0)[1])
    plane_alone = wenv.Occluders(positions, sphere_on_plane()[1][sphere_triangles:])
    far = wenv.Occluders(np.float32([[50, 50, -50], [51, 50, -50], [50, 51, -50]]), np.array([[0, 1, 2]]))
    mat = wenv.Principled(base_color=(0.8, 0.3, 0.2), roughness=0.3)
    shader = wenv.Shader(BLACK, mat, quality="draft")
    kw = dict(occlusion=occlusion, bounce=None, positions=positions)

    def area(**more):
        return wenv.Lamp("AREA", placed((-1, 1, 3), shine=(0.3, -0.3, -1.0)), energy=400.0, size=1.2, **more)
    shadowed = shader.shade(normals, views, lamps=[area()], **kw)
    assert area(blockers=plane_alone).blockers is plane_alone and area().blockers is None
    assert np.array_equal(shader.shade(normals, views, lamps=[area(blockers=occluders)], **kw), shadowed)
    free = shader.shade(normals, views, lamps=[area(cast_shadow=False)], **kw)
    assert np.array_equal(shader.shade(normals, views, lamps=[area(blockers=far)], **kw), free)
    # the sphere excluded from what blocks the lamp: no contact shadow on the plane
    linked = shader.shade(normals, views, lamps=[area(blockers=plane_alone)], **kw)
    assert relative_rmse(shadowed, free) > 0.1 and relative_rmse(linked, free) < 0.01, relative_rmse(linked, free)
    ref = wenv.reference(BLACK, mat, normals, views, positions=positions, occluders=occluders,
                         lamps=[area(blockers=plane_alone)])
    assert relative_rmse(linked, ref) < 0.03, relative_rmse(linked, ref)
    # unshadowed calls stay so: a lamp's blockers only replace a scene's
    assert np.array_equal(shader.shade(normals, views, positions=positions, lamps=[area(blockers=occluders)]),
                          shader.shade(normals, views, positions=positions, lamps=[area()]))


def test_a_new_power_makes_nothing_again(contact):
    """What no view changes (shares and shadow cells) is kept while the lamps stay where they are:
    a new power or colour only scales; a moved lamp casts again."""
    positions, normals, views, _, occlusion = contact
    shader = wenv.Shader(BLACK, wenv.Lambert(0.5), quality="draft")

    def shade(**kw):
        lamp = wenv.Lamp("POINT", placed(kw.pop("at", (1.5, -1.0, 2.5))), radius=0.3, **kw)
        return shader.shade(normals, views, occlusion=occlusion, bounce=None, positions=positions, lamps=[lamp])
    a = shade(energy=100.0)
    made = shader.stats["lamp_light_made"]
    b = shade(energy=300.0, color=(1.0, 0.5, 0.25))
    assert shader.stats["lamp_light_made"] == made
    assert np.allclose(b, a * np.float32([3.0, 1.5, 0.75]), rtol=1e-5, atol=1e-7)
    shade(energy=100.0, at=(1.0, -1.0, 2.5))
    assert shader.stats["lamp_light_made"] == made + 1


def test_a_moved_lamp_is_made_alone_and_right(contact):
    """Of two lamps, one moved: only its part is made again, and the result is a fresh shader's."""
    positions, normals, views, _, occlusion = contact
    sun = wenv.Lamp("SUN", placed((0, 0, 0), shine=(0.5, 0.3, -1.0)), energy=3.0, angle=0.1)

    def area(z):
        return wenv.Lamp("AREA", placed((-1, 1, z), shine=(0.3, -0.3, -1.0)), energy=400.0, size=1.2)
    kept = wenv.Shader(BLACK, MATERIALS["paint"](), quality="draft")
    kw = dict(occlusion=occlusion, bounce=None, positions=positions)
    kept.shade(normals, views, lamps=[sun, area(3.0)], **kw)
    moved = kept.shade(normals, views, lamps=[sun, area(2.5)], **kw)
    fresh = wenv.Shader(BLACK, MATERIALS["paint"](), quality="draft").shade(normals, views, lamps=[sun, area(2.5)],
                                                                           **kw)
    assert np.array_equal(moved, fresh)


def test_shade_mesh_culled_and_in_steps_agrees(contact):
    """The lamps' rows follow culling and budgeted steps."""
    positions, normals, _, _, occlusion = contact
    eye = (4.0, -5.0, 4.0)
    shader = wenv.Shader(BLACK, MATERIALS["paint"](), quality="draft")
    lamps = [LAMPS["point"]()]
    whole = shader.shade_mesh(positions, normals, eye, occlusion=occlusion, lamps=lamps)
    culled = shader.shade_mesh(positions, normals, eye, cull=True, occlusion=occlusion, lamps=lamps)
    seen = wenv.visible_vertices(positions, normals, eye)
    assert np.allclose(culled[seen], whole[seen], rtol=1e-5, atol=1e-7)
    out = np.zeros_like(whole)
    first = 0
    while first < len(positions):
        shader.shade_mesh(positions, normals, eye, occlusion=occlusion, lamps=lamps, out=out, first=first, budget=0.0)
        first = shader.stats["next_vertex"]
    assert np.allclose(out, whole, rtol=1e-5, atol=1e-7)


# ---- bad input ----

@pytest.mark.parametrize("make, error, words", [
    (lambda: wenv.Lamp("POINT", energy=-1.0), ValueError, "energy"),
    (lambda: wenv.Lamp("POINT", energy=math.inf), ValueError, "energy"),
    (lambda: wenv.Lamp("POINT", energy=math.nan), ValueError, "energy"),
    (lambda: wenv.Lamp("LASER"), ValueError, "type"),
    (lambda: wenv.Lamp("AREA", shape="STAR"), ValueError, "shape"),
    (lambda: wenv.Lamp("AREA", spread=0.0), ValueError, "spread"),
    (lambda: wenv.Lamp("SPOT", spot_size=4.0), ValueError, "spot_size"),
    (lambda: wenv.Lamp("POINT", radius=-0.1), ValueError, "radius"),
    (lambda: wenv.Lamp("POINT", color=(1.0, -1.0, 0.0)), ValueError, "color"),
    (lambda: wenv.Lamp("SUN", [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, math.nan, 0], [0, 0, 0, 1]]), ValueError, "matrix"),
    (lambda: wenv.Lamp("SPOT", np.diag([1.0, 0.0, 1.0, 1.0])), ValueError, "singular"),
])
def test_bad_lamps_are_named(make, error, words):
    with pytest.raises(error, match=words):
        make()


def test_bad_lamp_calls_are_named():
    positions, normals, views = lit_sphere(10)
    shader = wenv.Shader(BLACK, wenv.Lambert(0.5), quality="draft")
    lamp = LAMPS["point"]()
    with pytest.raises(ValueError, match="positions"):
        shader.shade(normals, views, lamps=[lamp])
    with pytest.raises(TypeError, match=r"lamps\[0\]"):
        shader.shade(normals, views, positions=positions, lamps=["sun"])
    bad = positions.copy()
    bad[3, 1] = math.nan
    with pytest.raises(ValueError, match=r"positions\[3\]"):
        shader.shade(normals, views, positions=bad, lamps=[lamp])
    with pytest.raises(ValueError, match="rows"):
        shader.shade(normals, views, positions=positions[:5], lamps=[lamp])
    with pytest.raises(ValueError, match="positions"):
        wenv.reference(BLACK, wenv.Lambert(0.5), normals, views, lamps=[lamp])
    assert np.array_equal(shader.shade(normals, views, positions=positions, lamps=[]), shader.shade(normals, views))
