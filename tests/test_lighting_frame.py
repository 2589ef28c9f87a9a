"""The method holds an image at rotation 0 and strength 1; a World's rotation turns the normals and
views and its strength scales the result (methods/lighting_frame.h), so a new rotation or strength
remakes nothing.  Shading under a turned World must equal shading the turned normals and views under
the unturned one -- to the bit, which shows nothing was remade -- whatever was set before, and stay
as close to wenv.reference as the unturned World's shading is to its own."""
import math

import numpy as np
import pytest

import wenv
from test_culling import sphere

SETTINGS = [("rotation", "draft"), ("slicing", "default"), ("split_sum", "draft"), ("sh", "draft")]


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(11)
    img = np.float32(rng.uniform(0.05, 1.0, (32, 64, 3)))
    img[8:11, 20:24] = 40.0  # a lamp: the exact lights take it
    env = wenv.Environment(img)
    mat = wenv.CookTorrance(diffuse=0.3, lobes=[{"specular": 0.8, "alpha": 0.2, "ior": 1.5}])
    n = rng.normal(size=(400, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v = rng.normal(size=(400, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v *= np.sign(np.sum(n * v, axis=1, keepdims=True))
    return env, mat, np.float32(n), np.float32(v + 1e-3 * n)


def turn_z(a, angle):
    """R_z(angle) a in float32, term by term in the core's order (no BLAS: its fused multiply-adds
    would differ in the last bit)."""
    c, s, zero = np.float32(math.cos(angle)), np.float32(math.sin(angle)), np.float32(0.0)
    x, y, z = a[:, 0], a[:, 1], a[:, 2]
    return np.ascontiguousarray(np.stack([c * x + -s * y + zero * z, s * x + c * y + zero * z,
                                          zero * x + zero * y + np.float32(1.0) * z], axis=1))


def rel_rmse(x, ref):
    return float(np.sqrt(np.mean((x - ref) ** 2) / np.mean(ref ** 2)))


@pytest.mark.parametrize("method,quality", SETTINGS)
def test_a_turned_world_turns_the_normals_and_views(scene, method, quality):
    env, mat, n, v = scene
    held = wenv.Shader(env, mat, quality=quality, method=method, cache_dir=False)
    turned = wenv.Shader(env, mat, quality=quality, method=method, cache_dir=False)
    world = env.with_transform(rotation=1.1, strength=2.5)
    turned.set_environment(world)
    assert turned.environment is world
    got = turned.shade(n, v)
    # the same method state, read at the turned directions and scaled by the strength
    expected = held.shade(turn_z(n, 1.1), turn_z(v, 1.1)) * np.float32(2.5)
    assert np.array_equal(got, expected)
    # the same as a shader made for it: the result does not depend on what was set before
    assert np.array_equal(got, wenv.Shader(world, mat, quality=quality, method=method, cache_dir=False).shade(n, v))
    # and it is the turned World: as near the reference as the unturned World's shading is to its own
    err = rel_rmse(got, wenv.reference(world, mat, n, v))
    err_held = rel_rmse(held.shade(n, v), wenv.reference(env, mat, n, v))
    assert err < 1.5 * err_held + 0.01, (err, err_held)


def test_turns_compose_and_turning_back_is_the_held_state(scene):
    env, mat, n, v = scene
    shader = wenv.Shader(env, mat, quality="default", method="slicing")
    first = shader.shade(n, v)
    for angle in (0.4, -2.0, 7.0):
        shader.set_environment(env.with_transform(rotation=angle))
    shader.set_environment(env.with_transform(rotation=0.0))
    assert np.array_equal(shader.shade(n, v), first)


def test_another_image_goes_to_the_method_and_a_black_world_keeps_its_image(scene):
    env, mat, n, v = scene
    other = wenv.Environment(np.float32(np.random.default_rng(12).uniform(0.05, 1.0, (32, 64, 3))))
    shader = wenv.Shader(env, mat, quality="default", method="slicing")
    shader.set_environment(other)
    assert np.array_equal(shader.shade(n, v), wenv.Shader(other, mat, quality="default", method="slicing").shade(n, v))
    shader.set_environment(env.with_transform(strength=0.0))
    assert not shader.shade(n, v).any()
    bright = env.with_transform(rotation=0.3, strength=1.5)
    shader.set_environment(bright)
    assert np.array_equal(shader.shade(n, v), wenv.Shader(bright, mat, quality="default", method="slicing").shade(n, v))


def test_one_pixel_changed_is_another_image(scene):
    """The image's fingerprint is made with it and kept by its turned copies: a copy with one pixel
    changed (the same shape) goes to the method anew, a turned copy does not."""
    env, mat, n, v = scene
    img = env.pixels[..., :3].copy()
    img[9, 21, 1] += np.float32(0.5)  # a tint in the lamp
    tinted = wenv.Environment(img)
    shader = wenv.Shader(env, mat, quality="default", method="slicing")
    held = shader.shade(n, v)
    shader.set_environment(tinted.with_transform(rotation=0.5))
    got = shader.shade(n, v)
    assert not np.array_equal(got, held)
    assert np.array_equal(got, wenv.Shader(tinted.with_transform(rotation=0.5), mat, quality="default",
                                           method="slicing").shade(n, v))


def test_an_image_too_bright_for_strength_one_is_held_at_its_own(scene):
    """Pixels of 1e20 at strength 0.001 are a valid World, the same pixels at strength 1 are not
    (1e18 at most, envmap.h): the method holds them at the World's strength, which then cannot be
    scaled; a new strength gives the image anew, a new rotation still only turns."""
    _, mat, n, v = scene
    img = np.full((16, 32, 3), 1e20, np.float32)
    img[:8] *= np.float32(0.2)
    env = wenv.Environment(img, strength=1e-3)
    shader = wenv.Shader(env, mat, quality="draft", method="slicing")
    for world in (env.with_transform(rotation=0.8), env.with_transform(rotation=0.8, strength=2e-3)):
        shader.set_environment(world)
        fresh = wenv.Shader(world, mat, quality="draft", method="slicing").shade(n, v)
        assert np.array_equal(shader.shade(n, v), fresh) and np.all(np.isfinite(fresh)) and fresh.max() > 1e13


def test_refinement_steps_under_a_turned_world_equal_one_call(scene):
    env, mat, _, _ = scene
    pos, nrm = sphere(6000, seed=3)
    eye = (0.3, -3.0, 1.2)
    shader = wenv.Shader(env, mat, quality="default", method="slicing")
    shader.set_environment(env.with_transform(rotation=2.0))
    whole = shader.shade_mesh(pos, nrm, eye, cull=True)
    out, first = np.zeros_like(whole), 0
    while first < shader.stats.get("visible_vertices", len(pos)):
        shader.shade_mesh(pos, nrm, eye, cull=True, out=out, first=first, budget=0.0)
        assert shader.stats["next_vertex"] > first
        first = shader.stats["next_vertex"]
    assert np.array_equal(out, whole)
