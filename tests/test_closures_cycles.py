"""Shader nodes other than the Principled BSDF against Cycles: a Diffuse BSDF (smooth and rough), a
coloured Glossy BSDF, a Metallic BSDF, a Sheen BSDF, and Mix and Add Shaders of them inside a node
group, each read by the add-on (addon/closures.py) as Principled terms times weights, on Cycles'
unoccluded sphere under sunset (at half its size: a quarter of the pixels for the references to
sum): the terms' references summed by their weights against Cycles' render, within its noise."""
import math

import numpy as np
import pytest

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

import wenv  # noqa: E402
from addon import closures, compat, engine  # noqa: E402
from tests.helpers.cycles_sphere import SphereScene, halved_hdri  # noqa: E402
from tests.helpers.blender_versions import node_material as new_node_material  # noqa: E402


@pytest.fixture(scope="module")
def sphere():
    return SphereScene("sunset", size=48, samples=384, image=halved_hdri("sunset"))


def node_material(build):
    """A material whose output's Surface is what build(tree) returns (an output socket)."""
    mat = new_node_material(bpy, "wenv-closures")
    tree = mat.node_tree
    for n in list(tree.nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            tree.nodes.remove(n)
    tree.links.new(build(tree), tree.nodes["Material Output"].inputs["Surface"])
    return mat


def bsdf(tree, kind, **inputs):
    node = tree.nodes.new(kind)
    for key, value in inputs.items():
        if key in ("distribution", "fresnel_type"):
            setattr(node, key, value)
            continue
        sock = node.inputs[key]
        sock.default_value = tuple(value) + (1.0,) if isinstance(value, tuple) and len(sock.default_value) == 4 else value
    return node.outputs[0]


def mix(tree, fac, a, b):
    node = tree.nodes.new("ShaderNodeMixShader")
    node.inputs[0].default_value = fac
    tree.links.new(a, node.inputs[1])
    tree.links.new(b, node.inputs[2])
    return node.outputs[0]


def grouped(tree, build):
    """build(inner tree) inside a node group, its shader out through the group's output."""
    group = bpy.data.node_groups.new("wenv-group", "ShaderNodeTree")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    out = group.nodes.new("NodeGroupOutput")
    group.links.new(build(group), out.inputs[0])
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    return node.outputs[0]


CASES = {
    "diffuse": lambda t: bsdf(t, "ShaderNodeBsdfDiffuse", Color=(0.6, 0.4, 0.2), Roughness=0.0),
    "rough diffuse": lambda t: bsdf(t, "ShaderNodeBsdfDiffuse", Color=(0.6, 0.4, 0.2), Roughness=0.6),
    "glossy": lambda t: bsdf(t, "ShaderNodeBsdfGlossy", Color=(0.8, 0.5, 0.3), Roughness=0.3, distribution="GGX"),
    "metallic": lambda t: bsdf(t, "ShaderNodeBsdfMetallic", **{"Base Color": (0.9, 0.6, 0.3), "Edge Tint": (0.9, 0.8, 0.7),
                                                                "Roughness": 0.35}),
    "sheen": lambda t: bsdf(t, "ShaderNodeBsdfSheen", Color=(0.7, 0.7, 0.9), Roughness=0.4),
    "mix in a group": lambda t: grouped(t, lambda g: mix(
        g, 0.3, bsdf(g, "ShaderNodeBsdfDiffuse", Color=(0.5, 0.2, 0.1)),
        bsdf(g, "ShaderNodeBsdfGlossy", Color=(1.0, 1.0, 1.0), Roughness=0.25, distribution="MULTI_GGX"))),
    "add": lambda t: _add(t, bsdf(t, "ShaderNodeBsdfDiffuse", Color=(0.3, 0.3, 0.5)),
                          bsdf(t, "ShaderNodeBsdfGlossy", Color=(0.4, 0.4, 0.4), Roughness=0.4, distribution="GGX")),
}


def _add(tree, a, b):
    node = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(a, node.inputs[0])
    tree.links.new(b, node.inputs[1])
    return node.outputs[0]


@pytest.mark.parametrize("case", [c for c in CASES if c != "metallic" or hasattr(bpy.types, "ShaderNodeBsdfMetallic")])
def test_shader_nodes_match_cycles_within_its_noise(sphere, case):
    """(The Metallic BSDF came with Blender 4.3; before it, a rough Diffuse BSDF is Cycles' classic
    Oren-Nayar, 4 % from the energy-preserving one here: each Blender's own is shaded.)"""
    mat = node_material(CASES[case])
    sphere._use(mat)
    found, notes = closures.terms(mat)
    assert found and not notes, notes
    if case == "rough diffuse":
        assert found[0].inputs.get("oren_nayar", "energy_preserving") == (
            "classic" if compat.DIFFUSE_OREN_NAYAR_CLASSIC else "energy_preserving")
    env = sphere.environment()
    ref = sum(np.float64(t.colour) * wenv.reference(env, engine.principled(t.inputs), sphere.normals, sphere.views)
              for t in found)
    a, b = (sphere.render(seed)[sphere.mask].astype(np.float64) for seed in (1, 2))
    scale = math.sqrt(float(np.mean(ref ** 2)))
    noise_of_mean = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale / math.sqrt(2)
    error = math.sqrt(float(np.mean(((a + b) / 2 - ref) ** 2))) / scale
    # the mean's own noise, with room for its spread and the sphere's facets
    assert error < 1.5 * noise_of_mean + 0.01, (error, noise_of_mean)
