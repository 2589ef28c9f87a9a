"""Shading with the scene in the way: the wavelet methods with an Occlusion against the reference that
casts every pixel's ray, a convex mesh unchanged to the bit, the blockers' light (bounce), the exact
lights tested along their own rays, the World turned, and bad input."""
import numpy as np
import pytest

import wenv
from tests.helpers.meshes import box, merged, square, uv_sphere


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))


def sky(sun=None, height=64):
    """sky_pixels as a wenv.Environment."""
    return wenv.Environment(sky_pixels(sun, height))


def sky_pixels(sun=None, height=64):
    """An equirect sky brighter overhead than at the horizon over a dark brown ground, with an
    optional sun: 4 pixels 5000x the mean (taken out as exact lights) at (azimuth, elevation) in
    degrees."""
    w = 2 * height
    el = (0.5 - (np.arange(height) + 0.5) / height) * np.pi
    px = np.empty((height, w, 3), np.float32)
    up = np.clip(np.sin(el), 0.0, None)[:, None]
    px[:] = (0.35 + 0.65 * up)[:, :, None] * np.array([0.55, 0.7, 1.0], np.float32)
    px[el < 0] = (0.12, 0.08, 0.05)
    if sun is not None:
        az, e = sun
        j = int((0.5 - e / 180.0) * height)
        i = int(((-az / 360.0) + 0.5) % 1.0 * w)  # Blender's equirect: +X at the centre, azimuth anticlockwise
        px[j:j + 2, i:i + 2] = 5000.0
    return px


def sphere_on_plane():
    """A sphere resting on a square (a contact shadow), with each vertex's normal."""
    sv, sf = uv_sphere(16, 32, 1.0)
    sv = sv + np.array([0.0, 0.0, 1.0], np.float32)
    g = np.linspace(-3.0, 3.0, 25, dtype=np.float32)
    x, y = np.meshgrid(g, g)
    pv = np.stack([x.ravel(), y.ravel(), np.zeros(x.size, np.float32)], 1)
    pf = [(j * 25 + i, j * 25 + i + 1, (j + 1) * 25 + i + 1) for j in range(24) for i in range(24)]
    pf += [(j * 25 + i, (j + 1) * 25 + i + 1, (j + 1) * 25 + i) for j in range(24) for i in range(24)]
    positions, triangles = merged((sv, sf), (pv, np.array(pf)))
    normals = np.vstack([sv - np.array([0.0, 0.0, 1.0], np.float32), np.tile([0.0, 0.0, 1.0], (len(pv), 1))])
    return positions, triangles, (normals / np.linalg.norm(normals, axis=1)[:, None]).astype(np.float32)


@pytest.fixture(scope="module")
def scene():
    positions, triangles, normals = sphere_on_plane()
    occluders = wenv.Occluders(positions, triangles)
    occlusion = occluders.occlusion(positions, normals, resolution=8)
    eye = np.array([0.5, -6.0, 4.0], np.float32)
    views = (eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]
    front = np.einsum("ij,ij->i", normals, views) > 0.05
    return positions, normals, views.astype(np.float32), occluders, occlusion, np.flatnonzero(front)[::3], triangles


MATERIALS = {
    "lambert": wenv.Lambert(0.7),
    "glossy": wenv.CookTorrance(0.3, [dict(alpha=0.25, specular=1.0, ior=1.5)]),
}


@pytest.mark.parametrize("sun", [None, (30.0, 35.0)], ids=["sky", "sun"])
@pytest.mark.parametrize("name", list(MATERIALS))
def test_shadowed_shading_matches_the_shadowed_reference(scene, name, sun):
    """Against the reference casting every pixel's ray with the same bounce: within 4 % relative RMSE
    (measured 1.6-2.6 %), where leaving the scene out is off by 15 % or more."""
    positions, normals, views, occluders, occlusion, idx, _ = scene
    env, mat = sky(sun), MATERIALS[name]
    shader = wenv.Shader(env, mat, quality="default")
    light = shader.diffuse_light(normals, occlusion=occlusion)
    shaded = shader.shade(normals, views, occlusion=occlusion, bounce=light)
    truth = wenv.reference(env, mat, normals[idx], views[idx], positions=positions[idx], occluders=occluders,
                           bounce=light)
    assert relative_rmse(shaded[idx], truth) < 0.04
    assert relative_rmse(shader.shade(normals, views)[idx], truth) > 0.15


def test_the_sun_casts_a_sharp_shadow(scene):
    """Under a sun, the plane's vertices inside the sphere's shadow and those just outside differ by
    the sun's light, as in the reference: the exact lights are tested along their own rays, not
    through the 22-degree texels of the masks."""
    positions, normals, views, occluders, occlusion, _, _ = scene
    env, mat = sky((30.0, 35.0)), MATERIALS["lambert"]
    shader = wenv.Shader(env, mat, quality="default")
    plane = np.flatnonzero(positions[:, 2] == 0.0)
    shaded = shader.shade(normals, views, occlusion=occlusion, bounce=None)[plane]
    truth = wenv.reference(env, mat, normals[plane], views[plane], positions=positions[plane], occluders=occluders)
    in_shadow = truth.sum(1) < 0.5 * np.median(truth.sum(1))
    assert 5 <= in_shadow.sum() < len(plane) // 2
    assert np.array_equal(shaded.sum(1) < 0.5 * np.median(truth.sum(1)), in_shadow)
    assert relative_rmse(shaded, truth) < 0.03


def test_the_blockers_light_fills_the_shadow(scene):
    """bounce='self' (the occluders are the shaded vertices) equals passing the mesh's own diffuse
    light, brightens the contact shadow, and None leaves blocked directions black."""
    positions, normals, views, occluders, occlusion, idx, _ = scene
    shader = wenv.Shader(sky(), MATERIALS["lambert"], quality="default")
    own = shader.shade(normals, views, occlusion=occlusion)
    given = shader.shade(normals, views, occlusion=occlusion, bounce=shader.diffuse_light(normals, occlusion=occlusion))
    black = shader.shade(normals, views, occlusion=occlusion, bounce=None)
    np.testing.assert_allclose(own, given, rtol=1e-5, atol=1e-7)
    contact = np.flatnonzero((positions[:, 2] == 0.0) & (np.hypot(positions[:, 0], positions[:, 1]) < 0.8))
    assert len(contact) and np.all(own[contact] >= black[contact])
    assert own[contact].sum() > 1.05 * black[contact].sum()


def test_point_rays_catch_what_coarse_masks_miss():
    """A thin pole's shadow from a sun on the ground: 8 x 8 masks' rays pass beside the pole far from
    it, so without point rays the sun reaches most of the shadow's line; with point_rays=True every
    point casts the sun's ray and the line is dark, as the ray-cast reference has it.  Points that
    see their whole sky shade as without occlusion, within half a per cent.  with_point_rays() makes
    the same from the masks cast without."""
    pole = box((-0.1, -0.1, 0.0), (0.1, 0.1, 3.0))
    ground = square(6.0, 0.0)
    occluders = wenv.Occluders(*merged(ground, pole))
    height = 64
    i = int(((-30.0 / 360.0) + 0.5) % 1.0 * 2 * height)  # the sun's 2 x 2 pixels, as sky_pixels puts them
    j = int((0.5 - 35.0 / 180.0) * height)
    az, el = np.radians((0.5 - (i + 1) / (2 * height)) * 360.0), np.radians((0.5 - (j + 1) / height) * 180.0)
    away = -np.array([np.cos(az), np.sin(az)])  # the shadow falls away from the sun
    d = np.linspace(0.5, 3.5, 24)
    line = np.column_stack([d * away[0], d * away[1], np.zeros_like(d)])
    open_ground = np.column_stack([d * away[1] + 4.0, -d * away[0], np.zeros_like(d)])  # far beside it
    points = np.vstack([line, open_ground]).astype(np.float32)
    up = np.tile(np.float32([0, 0, 1]), (len(points), 1))
    views = np.tile(np.float32([0.0, -0.6, 0.8]), (len(points), 1))
    env, mat = sky((30.0, 35.0)), wenv.Lambert(0.8)
    shader = wenv.Shader(env, mat, quality="default")
    coarse = occluders.occlusion(points, up, resolution=8)
    pointed = occluders.occlusion(points, up, resolution=8, point_rays=True)
    assert pointed.point_rays and not coarse.point_rays and pointed.blocked_vertices == len(points)
    truth = wenv.reference(env, mat, up, views, positions=points, occluders=occluders)
    plain = shader.shade(up, views)
    with_masks = shader.shade(up, views, occlusion=coarse, bounce=None)
    with_rays = shader.shade(up, views, occlusion=pointed, bounce=None)
    shadow = slice(0, len(line))
    assert np.all(truth[shadow].sum(1) < 0.5 * plain[shadow].sum(1))  # the sun is most of the light
    missed = with_masks[shadow].sum(1) > 0.9 * plain[shadow].sum(1)  # the sun passing between the rays
    assert missed.sum() >= len(line) // 2
    np.testing.assert_allclose(with_rays[shadow], truth[shadow], rtol=0.05)
    # the lights walked with visibility (a wide cluster read by its parts): within half a per cent
    np.testing.assert_allclose(with_rays[len(line):], plain[len(line):], rtol=5e-3)
    # made from the masks cast without: the same masks and hits, no ray cast, the same shading
    converted = coarse.with_point_rays()
    assert converted.point_rays and converted.cast_vertices == 0 and converted.blocked_vertices == len(points)
    np.testing.assert_array_equal(converted.visible, pointed.visible)
    np.testing.assert_array_equal(converted.triangles, pointed.triangles)
    np.testing.assert_array_equal(shader.shade(up, views, occlusion=converted, bounce=None), with_rays)
    with pytest.raises(ValueError, match="point_rays"):
        occluders.occlusion(points, up, previous=pointed, changed=(0, 0), point_rays=False)
    assert occluders.occlusion(points, up, previous=pointed, changed=(0, 0)).point_rays


def test_shared_masks_keep_each_point_s_own_rays():
    """masks_from: points along a pole's shadow each read the mask of a point beside the shadow (a
    bake's neighbouring texels share one), which alone is cast.  Each point still casts its own
    lights' rays from where it is: those in the shadow are dark and those beside it lit, as the
    reference has them, and the soft part read from the mask is the owner's."""
    pole = box((-0.1, -0.1, 0.0), (0.1, 0.1, 3.0))
    occluders = wenv.Occluders(*merged(square(6.0, 0.0), pole))
    height = 64
    i = int(((-30.0 / 360.0) + 0.5) % 1.0 * 2 * height)
    j = int((0.5 - 35.0 / 180.0) * height)
    az = np.radians((0.5 - (i + 1) / (2 * height)) * 360.0)
    away, side = -np.array([np.cos(az), np.sin(az)]), np.array([np.sin(az), -np.cos(az)])
    d = np.linspace(0.5, 3.5, 16)
    beside = np.column_stack([d * away[0] + 0.35 * side[0], d * away[1] + 0.35 * side[1], np.zeros_like(d)])
    line = np.column_stack([d * away[0], d * away[1], np.zeros_like(d)])
    points = np.vstack([beside, line]).astype(np.float32)
    up = np.tile(np.float32([0, 0, 1]), (len(points), 1))
    views = np.tile(np.float32([0.0, -0.6, 0.8]), (len(points), 1))
    env, mat = sky((30.0, 35.0)), wenv.Lambert(0.8)
    shader = wenv.Shader(env, mat, quality="default")
    owners = np.arange(len(d))
    masks_from = np.concatenate([owners, owners])  # each shadow point reads the mask of the one beside it
    shared = occluders.occlusion(points, up, resolution=4, point_rays=True, masks_from=masks_from)
    own = occluders.occlusion(points, up, resolution=4, point_rays=True)
    assert shared.blocked_vertices == shared.cast_vertices == len(d)
    np.testing.assert_array_equal(shared.visible[len(d):], own.visible[:len(d)])
    np.testing.assert_array_equal(shared.visible[:len(d)], own.visible[:len(d)])
    assert (shared.hits["vertex"] < len(d)).all()
    truth = wenv.reference(env, mat, up, views, positions=points, occluders=occluders)
    got = shader.shade(up, views, occlusion=shared, bounce=None)
    assert np.all(truth[len(d):].sum(1) < 0.5 * truth[:len(d)].sum(1))  # the sun is most of the light
    np.testing.assert_allclose(got, truth, rtol=0.05)
    for bad, match in ((np.concatenate([owners + len(d), owners]), "reads its own"),
                       (np.full(len(points), len(points)), "vertex index"), (owners, "one vertex index per vertex")):
        with pytest.raises(ValueError, match=match):
            occluders.occlusion(points, up, resolution=4, point_rays=True, masks_from=bad)
    with pytest.raises(ValueError, match="point_rays"):
        occluders.occlusion(points, up, resolution=4, masks_from=masks_from)
    with pytest.raises(ValueError, match="previous"):
        occluders.occlusion(points, up, previous=own, changed=(0, 0), point_rays=True, masks_from=masks_from)
    with pytest.raises(ValueError, match="shares masks"):
        occluders.occlusion(points, up, previous=shared, changed=(0, 0))
    with pytest.raises(ValueError, match="shares masks"):
        shared.with_point_rays()


def test_point_rays_blur_a_metal_lobe_s_mirror_image():
    """A metal (alpha 0.09) on the ground mirrors a wall's top edge: its lobe is narrower than a 4 x 4
    mask's texel, so each point reads it through rays of its own.  With point rays a point casts
    nine about the mirror direction (half vectors at the lobe's slope quantiles), and the edge's
    mirror image is blurred as the reference's is: points part-way across read part of the sky,
    where the mirror ray alone gives all or nothing (measured: 13 % relative RMSE along the line,
    at most 0.22 of the open shading off at a step of the nine rays' shares; 16 % with 16 x 16
    masks' shares)."""
    wall = box((-3.0, 2.0, 0.0), (3.0, 2.2, 1.0))
    occluders = wenv.Occluders(*merged(square(6.0, 0.0), wall))
    y = np.linspace(0.2, 1.6, 29)
    points = np.column_stack([np.zeros_like(y), y, np.zeros_like(y)]).astype(np.float32)
    up = np.tile(np.float32([0, 0, 1]), (len(points), 1))
    views = np.tile(np.float32([0.0, -np.sqrt(0.5), np.sqrt(0.5)]), (len(points), 1))  # the mirror ray: 45 degrees up
    env = sky()
    metal = wenv.CookTorrance(0.0, [dict(alpha=0.09, specular=1.0, ior=1.5)])
    shader = wenv.Shader(env, metal, quality="default")
    truth = wenv.reference(env, metal, up, views, positions=points, occluders=occluders)
    plain = shader.shade(up, views)
    with_rays = shader.shade(up, views, occlusion=occluders.occlusion(points, up, resolution=4, point_rays=True),
                             bounce=None)
    seen, seen_truth = with_rays.sum(1) / plain.sum(1), truth.sum(1) / plain.sum(1)
    # the mirror ray leaves the wall at y = 1: the reference's blur spans a good part of the line
    partial = (seen_truth > 0.15) & (seen_truth < 0.85)
    assert partial.sum() >= 5
    assert np.count_nonzero((seen > 0.15) & (seen < 0.85) & partial) >= partial.sum() - 2
    assert np.abs(seen - seen_truth).max() < 0.25
    assert relative_rmse(with_rays, truth) < 0.16
    # the mirror ray alone, as a narrower lobe has it, jumps from dark to open
    mirror = wenv.CookTorrance(0.0, [dict(alpha=0.01, specular=1.0, ior=1.5)])
    sharp = wenv.Shader(env, mirror, quality="default")
    jump = sharp.shade(up, views, occlusion=occluders.occlusion(points, up, resolution=4, point_rays=True),
                       bounce=None).sum(1) / sharp.shade(up, views).sum(1)
    assert np.all((jump < 0.05) | (jump > 0.95))
    # with point rays the lobe is narrow at every side, so 16 x 16 masks read it through the same rays
    # (a bake's texels and its vertices' passes see it alike); the blocker sends nothing here
    fine = occluders.occlusion(points, up, resolution=16, point_rays=True)
    np.testing.assert_allclose(shader.shade(up, views, occlusion=fine, bounce=None), with_rays, rtol=1e-5, atol=1e-7)


def wall_under_bright_sky():
    """A wall's edge across a metal's lobes (alpha 0.09) at 29 points on the ground before it, seen at
    45 degrees, under a sky bright only above 45 degrees: (occluders, points, normals, views, env,
    material)."""
    wall = box((-3.0, 2.0, 0.0), (3.0, 2.2, 1.0))
    occluders = wenv.Occluders(*merged(square(6.0, 0.0), wall))
    y = np.linspace(0.2, 1.6, 29)
    points = np.column_stack([np.zeros_like(y), y, np.zeros_like(y)]).astype(np.float32)
    up = np.tile(np.float32([0, 0, 1]), (len(points), 1))
    views = np.tile(np.float32([0.0, -np.sqrt(0.5), np.sqrt(0.5)]), (len(points), 1))
    height = 64
    elevation = (0.5 - (np.arange(height) + 0.5) / height) * 180.0
    px = np.empty((height, 2 * height, 3), np.float32)
    px[:] = np.where(elevation > 45.0, 2.0, 0.05)[:, None, None] * np.array([0.55, 0.7, 1.0], np.float32)
    px[elevation < 0] = (0.12, 0.08, 0.05)
    return (occluders, points, up, views, wenv.Environment(px),
            wenv.CookTorrance(0.0, [dict(alpha=0.09, specular=1.0, ior=1.5)]))


def test_a_narrow_lobe_loses_the_light_its_blocker_hides_not_its_mean():
    """The wall of the test above, under a sky that is bright only above 45 degrees: where the wall's
    edge cuts the lower part of the metal's lobe, it hides the dim sky, and the points keep most of
    their light.  Each of the nine rays is weighed by the lighting along it (read from the
    lighting's pyramid), so the shading keeps the share of the light the open rays carry; the
    lobe's share alone, the lighting taken as uniform over it, darkened those points by the hidden
    share of the lobe (measured with the nine rays alone: 13 % relative RMSE along the line and at
    most 0.29 of the open shading off, against 30 % and 0.51; `default` casts finer rings where the
    nine disagree: 12 % and 0.22)."""
    occluders, points, up, views, env, metal = wall_under_bright_sky()
    y = np.linspace(0.2, 1.6, 29)  # the points' y
    shader = wenv.Shader(env, metal, quality="default")
    truth = wenv.reference(env, metal, up, views, positions=points, occluders=occluders)
    shaded = shader.shade(up, views, occlusion=occluders.occlusion(points, up, resolution=4, point_rays=True),
                          bounce=None)
    plain = shader.shade(up, views)
    assert relative_rmse(shaded, truth) < 0.18
    assert np.abs(shaded.sum(1) / plain.sum(1) - truth.sum(1) / plain.sum(1)).max() < 0.35
    # where the wall hides only dim sky the points stay near their open shading, as in the reference
    dim_hidden = (truth.sum(1) / plain.sum(1) > 0.9) & (y > 0.9)
    assert dim_hidden.sum() >= 3
    assert np.all(shaded[dim_hidden].sum(1) / plain[dim_hidden].sum(1) > 0.75)


def test_a_blocker_edge_across_a_lobe_is_read_on_finer_rings():
    """Where a narrow lobe's nine rays disagree, a blocker's edge crosses it: `lobe_rings` casts it
    again on finer rings, each ray weighed by the lighting along it.  Along the wall's line the
    worst point error falls with the rings (measured 0.29, 0.22 and 0.17 of the open shading at 0,
    4 and 8 rings), and points the wall does not reach keep their shading to the bit."""
    occluders, points, up, views, env, metal = wall_under_bright_sky()
    truth = wenv.reference(env, metal, up, views, positions=points, occluders=occluders)
    occlusion = occluders.occlusion(points, up, resolution=4, point_rays=True)
    plain = wenv.Shader(env, metal, quality={"lobe_rings": 0}).shade(up, views)
    shaded, worst, rmse = {}, {}, {}
    for rings in (0, 4, 8):
        shader = wenv.Shader(env, metal, quality={"lobe_rings": rings})
        shaded[rings] = shader.shade(up, views, occlusion=occlusion, bounce=None)
        worst[rings] = np.abs(shaded[rings].sum(1) / plain.sum(1) - truth.sum(1) / plain.sum(1)).max()
        rmse[rings] = relative_rmse(shaded[rings], truth)
    assert worst[4] < 0.85 * worst[0] and worst[8] < 0.7 * worst[0]
    assert rmse[8] < rmse[4] < rmse[0]
    # 1.5 further back, the lobes pass over the wall's top
    far = points[:8] - np.float32([0.0, 1.5, 0.0])
    far_occlusion = occluders.occlusion(far, up[:8], resolution=4, point_rays=True)
    assert np.allclose(wenv.reference(env, metal, up[:8], views[:8], positions=far, occluders=occluders),
                       wenv.reference(env, metal, up[:8], views[:8]), rtol=1e-3)
    far_shaded = [wenv.Shader(env, metal, quality={"lobe_rings": rings}).shade(
        up[:8], views[:8], occlusion=far_occlusion, bounce=None) for rings in (0, 8)]
    np.testing.assert_array_equal(far_shaded[0], far_shaded[1])


def test_each_hit_lies_on_its_ray(scene):
    """Occlusion.hits holds every blocked texel's ray, vertex by vertex: its vertex and triangle as
    Occlusion.triangles has them, and the hit point (the triangle's corners by its weights) on the
    ray from the vertex (lifted as the rays start) along its direction."""
    positions, normals, _, occluders, occlusion, _, triangles = scene
    hits = occlusion.hits
    blocked = occlusion.triangles.reshape(len(positions), -1)
    vertex, texel = np.nonzero(blocked >= 0)
    np.testing.assert_array_equal(hits["vertex"], vertex)
    np.testing.assert_array_equal(hits["triangle"], blocked[vertex, texel])
    np.testing.assert_allclose(hits["weights"].sum(1), 1.0, atol=1e-5)
    assert np.all(hits["weights"] >= -1e-6)
    point = np.einsum("hc,hcx->hx", hits["weights"], positions[triangles[hits["triangle"]]])
    start = positions[vertex] + occluders.offset * normals[vertex]
    along = point - start
    d = hits["direction"]
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    reach = np.einsum("hx,hx->h", along, d)
    assert np.all(reach > 0)
    off = np.linalg.norm(along - reach[:, None] * d, axis=1)
    assert np.all(off <= 1e-3 * reach + 1e-4)
    # the directions are the texels' own, turned into each vertex's frame: open texels' are not there
    assert np.all(np.einsum("hx,hx->h", d, normals[vertex]) > 0)


def test_light_given_per_hit_is_read_as_given(scene):
    """bounce_hits, each occluder vertex's light interpolated at each hit, shades as bounce given per
    vertex (for shade and shade_mesh); twice the light per hit fills the shadow with twice the light;
    bad bounce_hits are named."""
    positions, normals, views, occluders, occlusion, idx, triangles = scene
    shader = wenv.Shader(sky((30.0, 35.0)), MATERIALS["glossy"], quality="default")
    light = shader.diffuse_light(normals, occlusion=occlusion)
    hits = occlusion.hits
    at_hits = np.einsum("hc,hcx->hx", hits["weights"], light[triangles[hits["triangle"]]]).astype(np.float32)
    per_vertex = shader.shade(normals, views, occlusion=occlusion, bounce=light)
    per_hit = shader.shade(normals, views, occlusion=occlusion, bounce_hits=at_hits)
    np.testing.assert_allclose(per_hit, per_vertex, rtol=2e-4, atol=1e-6)
    eye = np.float32([0.5, -6.0, 4.0])
    np.testing.assert_allclose(shader.shade_mesh(positions, normals, eye, occlusion=occlusion, bounce_hits=at_hits),
                               shader.shade_mesh(positions, normals, eye, occlusion=occlusion, bounce=light),
                               rtol=2e-4, atol=1e-6)
    black = shader.shade(normals, views, occlusion=occlusion, bounce=None)
    twice = shader.shade(normals, views, occlusion=occlusion, bounce_hits=2 * at_hits)
    np.testing.assert_allclose(twice - black, 2 * (per_hit - black), rtol=1e-3, atol=1e-5)
    with pytest.raises(ValueError, match="bounce_hits has 3 rows"):
        shader.shade(normals, views, occlusion=occlusion, bounce_hits=at_hits[:3])
    bad = at_hits.copy()
    bad[5] = -1.0
    with pytest.raises(ValueError, match=r"bounce_hits\[5\] is negative"):
        shader.shade(normals, views, occlusion=occlusion, bounce_hits=bad)
    bad[5] = np.nan
    with pytest.raises(ValueError, match=r"bounce_hits\[5\]"):
        shader.shade(normals, views, occlusion=occlusion, bounce_hits=bad)
    with pytest.raises(ValueError, match="not both"):
        shader.shade(normals, views, occlusion=occlusion, bounce=light, bounce_hits=at_hits)
    with pytest.raises(ValueError, match="only with occlusion"):
        shader.shade(normals, views, bounce_hits=at_hits)


def test_sending_maps_are_read_at_each_hit(scene):
    """Occlusion.read_sent: maps that send the same light every way give, at each hit, the hit
    triangle's corners' light by its weights; a map that sends light along one side of a vertex's
    frame alone is read on that side; sending_directions are unit, in each vertex's upper hemisphere;
    bad maps are named."""
    positions, normals, _, occluders, occlusion, _, triangles = scene
    hits = occlusion.hits
    light = np.random.default_rng(5).uniform(0.0, 2.0, (len(positions), 3)).astype(np.float32)
    flat = np.repeat(light[:, None, :], 64, axis=1)
    np.testing.assert_allclose(occlusion.read_sent(normals, flat),
                               np.einsum("hc,hcx->hx", hits["weights"], light[triangles[hits["triangle"]]]),
                               rtol=1e-5, atol=1e-6)
    directions = occlusion.sending_directions(8)
    assert directions.shape == (64, len(positions), 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=2), 1.0, atol=1e-5)
    assert np.all(np.einsum("tix,ix->ti", directions, normals) > 0)
    # light sent only towards directions of the world's +x side: the hits whose ray runs along -x
    # (so that the hit sends back along +x) read more than those along +x
    towards_x = np.where(directions[..., 0] > 0, 1.0, 0.0).astype(np.float32).transpose(1, 0)
    read = occlusion.read_sent(normals, np.repeat(towards_x[..., None], 3, axis=2))[:, 0]
    along = hits["direction"][:, 0]
    assert read[along < -0.5].mean() > 0.8 and read[along > 0.5].mean() < 0.2
    with pytest.raises(ValueError, match="one per occluder vertex"):
        occlusion.read_sent(normals[:5], flat)
    with pytest.raises(ValueError, match=r"sent must be"):
        occlusion.read_sent(normals, flat[:, :10])
    with pytest.raises(ValueError, match="side must be even"):
        occlusion.read_sent(normals, np.zeros((len(positions), 9, 3), np.float32))
    bad = flat.copy()
    bad[7, 3, 1] = -1.0
    with pytest.raises(ValueError, match=r"sent\[7\] is negative"):
        occlusion.read_sent(normals, bad)
    with pytest.raises(ValueError, match="side must be even"):
        occlusion.sending_directions(3)


def test_a_convex_mesh_shades_to_the_bit_as_without(one_thread):
    """A sphere alone blocks nothing: shading with its occlusion gives exactly today's colours, and so
    does a new lighting made after (the pyramid the shadows read is made in the same pass)."""
    v, f = uv_sphere(12, 24)
    occlusion = wenv.Occluders(v, f).occlusion(v, v)
    assert occlusion.blocked_vertices == 0
    views = np.tile(np.float32([0.3, -0.8, 0.5]), (len(v), 1))
    for mat in MATERIALS.values():
        shader = wenv.Shader(sky((10.0, 40.0)), mat, quality="default")
        plain = shader.shade(v, views)
        assert np.array_equal(shader.shade(v, views, occlusion=occlusion), plain)
        shader.set_environment(sky((100.0, 20.0)))
        again = shader.shade(v, views, occlusion=occlusion)
        assert np.array_equal(again, wenv.Shader(sky((100.0, 20.0)), mat, quality="default").shade(v, views))


def test_a_turned_world_is_shadowed_in_the_world(scene):
    """The masks and rays stay in the world while the method shades in the held image's frame: a World
    turned by 1 rad matches the reference under the same turned World."""
    positions, normals, views, occluders, occlusion, idx, _ = scene
    env, mat = sky((30.0, 35.0)).with_transform(rotation=1.0), MATERIALS["glossy"]
    shader = wenv.Shader(sky((30.0, 35.0)), mat, quality="default")
    shader.set_environment(env)
    shaded = shader.shade(normals, views, occlusion=occlusion, bounce=None)
    truth = wenv.reference(env, mat, normals[idx], views[idx], positions=positions[idx], occluders=occluders)
    assert relative_rmse(shaded[idx], truth) < 0.04


def test_a_new_scene_or_bounce_is_not_read_from_the_last(scene):
    """What a shader keeps for a scene follows the scene's content: another occlusion, or another
    bounce, gives what a fresh shader gives."""
    positions, normals, views, occluders, occlusion, _, triangles = scene
    lifted = positions + np.float32([0.0, 0.0, 0.0])
    lifted[positions[:, 2] > 0.0] += np.float32([0.0, 0.0, 0.5])   # the sphere raised off the plane
    moved = wenv.Occluders(lifted, triangles).occlusion(lifted, normals)
    env, mat = sky(), MATERIALS["lambert"]
    shader = wenv.Shader(env, mat, quality="default")
    shader.shade(normals, views, occlusion=occlusion)
    np.testing.assert_array_equal(shader.shade(normals, views, occlusion=moved),
                                  wenv.Shader(env, mat, quality="default").shade(normals, views, occlusion=moved))
    glow = np.full((len(positions), 3), 2.0, np.float32)
    np.testing.assert_array_equal(shader.shade(normals, views, occlusion=moved, bounce=glow),
                                  wenv.Shader(env, mat, quality="default").shade(normals, views, occlusion=moved,
                                                                                 bounce=glow))


def test_the_lights_rays_kept_from_one_view_answer_the_next(scene):
    """The lights' rays are asked once per vertex and kept while the lighting and the scene hold: a
    view shaded after others gives to the bit what a fresh shader gives, and so does a new lighting
    (what was kept for the last one is not read)."""
    positions, normals, views, occluders, occlusion, _, _ = scene
    mat = MATERIALS["glossy"]
    eye = np.array([-4.0, 3.0, 2.5], np.float32)
    other = ((eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]).astype(np.float32)
    shader = wenv.Shader(sky((30.0, 35.0)), mat, quality="default")
    shader.shade(normals, views, occlusion=occlusion)
    fresh = wenv.Shader(sky((30.0, 35.0)), mat, quality="default").shade(normals, other, occlusion=occlusion)
    np.testing.assert_array_equal(shader.shade(normals, other, occlusion=occlusion), fresh)
    shader.set_environment(sky((120.0, 25.0)))
    np.testing.assert_array_equal(
        shader.shade(normals, other, occlusion=occlusion),
        wenv.Shader(sky((120.0, 25.0)), mat, quality="default").shade(normals, other, occlusion=occlusion))


def wall_and_cube_on_plane(cube):
    """A plane (41 x 41 vertices) split by a wall, with `cube` ((positions, triangles), triangles 12 to
    12 + its count) on one side: the plane's positions and normals, and the occluders."""
    g = np.linspace(-3.0, 3.0, 41, dtype=np.float32)
    x, y = np.meshgrid(g, g)
    plane = np.stack([x.ravel(), y.ravel(), np.zeros(x.size, np.float32)], 1)
    faces = [(j * 41 + i, j * 41 + i + 1, (j + 1) * 41 + i + 1) for j in range(40) for i in range(40)]
    faces += [(j * 41 + i, (j + 1) * 41 + i + 1, (j + 1) * 41 + i) for j in range(40) for i in range(40)]
    parts = [box((-0.1, -3.0, 0.0), (0.1, 3.0, 2.0))] + ([cube] if cube else []) + [(plane, np.array(faces))]
    normals = np.tile(np.float32([0.0, 0.0, 1.0]), (len(plane), 1))
    return plane, normals, wenv.Occluders(*merged(*parts))


def test_a_moved_object_recasts_exactly_the_vertices_that_see_it():
    """A cube moved beside a wall: the occlusion made from the previous one casts again exactly the
    plane's vertices whose rays met the cube before or meet it now (not those behind the wall), and
    equals a new cast -- masks, triangles and the bounce read at the hits, to the bit."""
    plane, normals, before_occ = wall_and_cube_on_plane(box((1.3, -0.2, 0.0), (1.7, 0.2, 0.4)))
    _, _, after_occ = wall_and_cube_on_plane(box((1.8, 0.3, 0.0), (2.2, 0.7, 0.4)))
    before = before_occ.occlusion(plane, normals)
    fresh = after_occ.occlusion(plane, normals)
    refreshed = after_occ.occlusion(plane, normals, previous=before, changed=(12, 12))

    def sees_cube(o):
        return np.any((o.triangles >= 12) & (o.triangles < 24), axis=(1, 2))

    affected = sees_cube(before) | sees_cube(fresh)
    assert 0 < affected.sum() < 0.5 * len(plane)
    assert refreshed.cast_vertices == affected.sum() and fresh.cast_vertices == len(plane)
    np.testing.assert_array_equal(refreshed.triangles, fresh.triangles)
    glow = np.random.default_rng(3).uniform(0.0, 2.0, (len(plane) + 16, 3)).astype(np.float32)
    views = np.tile(np.float32([0.3, -0.5, 0.8]), (len(plane), 1))
    shader = wenv.Shader(sky((30.0, 35.0)), MATERIALS["glossy"], quality="draft")
    np.testing.assert_array_equal(shader.shade(normals, views, occlusion=refreshed, bounce=glow),
                                  shader.shade(normals, views, occlusion=fresh, bounce=glow))


@pytest.mark.parametrize("cube", ["replaced", "removed"])
def test_a_replaced_or_removed_object_shifts_the_rest(cube):
    """The changed triangles may become any number (a sphere of 144 for the cube's 12, or none): the
    triangles after them are renumbered, and the result is a new cast's."""
    plane, normals, before_occ = wall_and_cube_on_plane(box((1.3, -0.2, 0.0), (1.7, 0.2, 0.4)))
    v, f = uv_sphere(6, 12, 0.3)
    _, _, after_occ = wall_and_cube_on_plane((v + np.float32([2.0, 0.0, 0.3]), f) if cube == "replaced" else None)
    refreshed = after_occ.occlusion(plane, normals, previous=before_occ.occlusion(plane, normals), changed=(12, 12))
    np.testing.assert_array_equal(refreshed.triangles, after_occ.occlusion(plane, normals).triangles)


def test_a_change_of_the_scenes_size_casts_every_vertex():
    """The cube moved far out doubles the scene's size, and with it how far every ray starts off its
    surface: every vertex is cast, and the result is still a new cast's.  Moved a little past the
    plane's edge, the size grows but the start does not move: only what sees the cube is cast."""
    plane, normals, before_occ = wall_and_cube_on_plane(box((1.3, -0.2, 0.0), (1.7, 0.2, 0.4)))
    _, _, near = wall_and_cube_on_plane(box((2.9, -0.2, 0.0), (3.3, 0.2, 0.4)))
    assert near.size > before_occ.size and near.offset == before_occ.offset
    before = before_occ.occlusion(plane, normals)
    assert near.occlusion(plane, normals, previous=before, changed=(12, 12)).cast_vertices < len(plane)
    _, _, after_occ = wall_and_cube_on_plane(box((20.0, -0.2, 0.0), (20.4, 0.2, 0.4)))
    assert after_occ.offset > before_occ.offset
    refreshed = after_occ.occlusion(plane, normals, previous=before, changed=(12, 12))
    assert refreshed.cast_vertices == len(plane)
    np.testing.assert_array_equal(refreshed.triangles, after_occ.occlusion(plane, normals).triangles)


def test_a_previous_occlusion_that_does_not_fit_is_named():
    plane, normals, before_occ = wall_and_cube_on_plane(box((1.3, -0.2, 0.0), (1.7, 0.2, 0.4)))
    _, _, after_occ = wall_and_cube_on_plane(box((1.8, 0.3, 0.0), (2.2, 0.7, 0.4)))
    before = before_occ.occlusion(plane, normals)
    with pytest.raises(ValueError, match="triangle 12 before is not triangle 12 now"):
        after_occ.occlusion(plane, normals, previous=before, changed=(0, 12))   # the wall said changed, not the cube
    with pytest.raises(ValueError, match="other positions"):
        after_occ.occlusion(plane + np.float32([0.0, 0.0, 0.1]), normals, previous=before, changed=(12, 12))
    with pytest.raises(ValueError, match="other normals"):
        after_occ.occlusion(plane, normals + np.float32([0.1, 0.0, 0.0]), previous=before, changed=(12, 12))
    with pytest.raises(ValueError, match="not among"):
        after_occ.occlusion(plane, normals, previous=before, changed=(12, 10**6))
    with pytest.raises(ValueError, match="resolution 16 is not previous's"):
        after_occ.occlusion(plane, normals, resolution=16, previous=before, changed=(12, 12))
    with pytest.raises(ValueError, match="changed needs previous"):
        after_occ.occlusion(plane, normals, changed=(12, 12))
    with pytest.raises(TypeError, match="changed must be"):
        after_occ.occlusion(plane, normals, previous=before, changed=12)
    with pytest.raises(TypeError, match="previous must be a wenv.Occlusion"):
        after_occ.occlusion(plane, normals, previous="before", changed=(12, 12))


def test_auto_picks_the_finest_resolution_within_its_rays():
    """resolution='auto': 16 x 16 for a small mesh; for 100,000 vertices the finest whose rays stay
    within 2^23 (9: 8.1 M rays, where 10 would cast 10 M)."""
    v, f = uv_sphere(12, 24)
    assert wenv.Occluders(v, f).occlusion(v, v, resolution="auto").resolution == 16
    far = wenv.Occluders(*square(0.5, 50.0))
    points = np.random.default_rng(2).uniform(-1.0, 1.0, (100_000, 3)).astype(np.float32)
    assert far.occlusion(points, np.tile(np.float32([0, 0, 1]), (len(points), 1)), resolution="auto").resolution == 9
    with pytest.raises(ValueError, match="4 to 16 or 'auto'"):
        far.occlusion(v, v, resolution="fine")


def test_methods_without_shadows_say_so(scene):
    _, normals, views, _, occlusion, _, _ = scene
    for method in ("split_sum", "sh"):
        shader = wenv.Shader(sky(), MATERIALS["lambert"], method=method)
        with pytest.raises(ValueError, match="without shadows"):
            shader.shade(normals, views, occlusion=occlusion)


def test_bad_scenes_are_named(scene):
    positions, normals, views, occluders, occlusion, _, _ = scene
    shader = wenv.Shader(sky(), MATERIALS["lambert"], quality="draft")
    with pytest.raises(ValueError, match="made for"):
        shader.shade(normals[:10], views[:10], occlusion=occlusion)
    with pytest.raises(TypeError, match="occlusion"):
        shader.shade(normals, views, occlusion=occluders)
    with pytest.raises(ValueError, match="bounce has"):
        shader.shade(normals, views, occlusion=occlusion, bounce=np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="negative"):
        shader.shade(normals, views, occlusion=occlusion, bounce=-np.ones((len(positions), 3), np.float32))
    with pytest.raises(ValueError, match="not finite"):
        shader.shade(normals, views, occlusion=occlusion, bounce=np.full((len(positions), 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="only with occlusion"):
        shader.shade(normals, views, bounce=None)
    other, tris = box((-1, -1, -1), (1, 1, 1))
    small = wenv.Occluders(other, tris).occlusion(positions[:5], normals[:5])
    with pytest.raises(ValueError, match="bounce='self'"):
        shader.shade(normals[:5], views[:5], occlusion=small)
    with pytest.raises(ValueError, match="bounce is read only with occluders"):
        wenv.reference(sky(), MATERIALS["lambert"], normals[:2], views[:2], bounce=np.zeros((2, 3), np.float32))


def test_shade_mesh_culled_and_in_steps_shades_as_shade(scene):
    """shade_mesh with an occlusion: culled to what the eye sees, and in budgeted steps, each vertex
    gets what shade gives it (the culled rows are the occlusion's vertices they came from)."""
    positions, normals, _, _, occlusion, _, _ = scene
    eye = (0.5, -6.0, 4.0)
    shader = wenv.Shader(sky((30.0, 35.0)), MATERIALS["glossy"], quality="default")
    views = np.float32(eye) - positions
    whole = shader.shade(normals, views, occlusion=occlusion)
    culled = shader.shade_mesh(positions, normals, eye, cull=True, occlusion=occlusion)
    seen = shader.stats["visible_vertices"]
    facing = np.einsum("ij,ij->i", normals, views) > 0
    assert 0 < seen < len(positions) and seen == facing.sum()
    np.testing.assert_allclose(culled[facing], whole[facing], rtol=1e-5, atol=1e-7)
    assert np.all(culled[~facing] == 0.0)
    out = np.zeros_like(whole)
    first = 0
    while first < len(positions):
        shader.shade_mesh(positions, normals, eye, occlusion=occlusion, out=out, first=first, budget=0.0)
        first = shader.stats["next_vertex"]
    np.testing.assert_allclose(out, whole, rtol=1e-5, atol=1e-7)


def test_an_occlusion_over_the_memory_budget_is_refused():
    """The occlusion keeps to its occluders' memory budget: 10 M vertices are refused before a ray is
    cast, and a scene whose blocked texels' hits outgrow the budget stops with a ValueError, not an
    allocation of gigabytes."""
    v, f = box((-1, -1, -1), (1, 1, 1))
    occluders = wenv.Occluders(v, f, memory_budget_mb=16)
    many = np.zeros((10_000_000, 3), np.float32)
    with pytest.raises(ValueError, match="memory budget"):
        occluders.occlusion(many, many + np.float32([0, 0, 1]))
    inside = np.random.default_rng(0).uniform(-0.5, 0.5, (100_000, 3)).astype(np.float32)   # every ray blocked
    with pytest.raises(ValueError, match="outgrew the memory budget"):
        occluders.occlusion(inside, np.tile(np.float32([0, 0, 1]), (len(inside), 1)), resolution=16)


@pytest.mark.parametrize("method", ["rotation", "slicing"])
def test_both_wavelet_methods_shade_shadows(scene, method):
    """Rotation (its matrices) and slicing (resampled directly) share the shadows: each within 5 % of
    the shadowed reference at draft (measured 1.5-2.5 %), equal to each other within 1 %."""
    positions, normals, views, occluders, occlusion, idx, _ = scene
    env, mat = sky((30.0, 35.0)), MATERIALS["glossy"]
    shader = wenv.Shader(env, mat, method=method, quality="draft", cache_dir=False)
    light = shader.diffuse_light(normals, occlusion=occlusion)
    shaded = shader.shade(normals, views, occlusion=occlusion, bounce=light)
    truth = wenv.reference(env, mat, normals[idx], views[idx], positions=positions[idx], occluders=occluders,
                           bounce=light)
    assert relative_rmse(shaded[idx], truth) < 0.05
    other = wenv.Shader(env, mat, method="slicing" if method == "rotation" else "rotation", quality="draft",
                        cache_dir=False)
    assert relative_rmse(other.shade(normals, views, occlusion=occlusion, bounce=light), shaded) < 0.01


@pytest.mark.parametrize("sun", [None, (30.0, 35.0)], ids=["sky", "sun"])
def test_the_shadowed_reference_matches_cycles_within_its_noise(sun):
    """Truth from outside: a sphere resting on a square (a contact shadow over its lower half) under a
    small sky, Cycles with Max Bounces 0 (direct light through every shadow ray, two seeds) against
    wenv.reference casting every pixel's ray against the same triangles: within 1.5x the render's
    noise plus 0.5 %, as the unoccluded sphere is (tests/test_principled.py)."""
    from tests.helpers.cycles_sphere import SphereScene
    scene = SphereScene(size=40, samples=256, image=sky_pixels(sun, 32), ground=True)
    inputs = dict(base_color=(0.6, 0.15, 0.08), roughness=0.3)
    scene.principled(**inputs)
    r = scene.compare_shadowed(wenv.Principled(**inputs))
    shadowed = np.mean(r["reference"][scene.positions[:, 2] < -0.5]) < 0.8 * np.mean(r["reference"])
    assert shadowed  # the ground takes a visible share of the sphere's lower half's light
    assert r["error"] < 1.5 * r["noise_of_mean"] + 0.005, (r["error"], r["noise_of_mean"])
