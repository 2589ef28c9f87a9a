"""A material's shader nodes as Cycles sums their closures: each BSDF node wenv shades exactly is a
Principled BSDF of the same reflection (read from Cycles' kernel: docs/addon.md, "Shader nodes"),
times a weight -- Mix Shader factors and, for a Glossy BSDF, its colour -- so that the material is
sum_k weight_k x Principled_k, every term an ordinary core material.

Why Principled terms: Cycles' Diffuse BSDF is a Principled BSDF without specular (its Oren-Nayar
is the Principled's Diffuse Roughness, Blender 4.3+), its Metallic BSDF (F82) the Principled's metal
lobe with Edge Tint as Specular Tint, its Sheen BSDF the Principled's sheen over black, and its
Glossy BSDF (no Fresnel) the Principled's white metal times a colour; a Mix Shader is (1 - t) A + t B
and an Add Shader A + B of the closures' weights.  So every term is shaded, and read by the
glossmeter, by the code that is proven against Cycles already.  Node groups are walked through, as
Cycles flattens them."""
import numpy as np

from . import compat, engine, nodes

MAX_DEPTH = 64
WHITE = (1.0, 1.0, 1.0)


class Term:
    """One closure: Principled inputs (wenv names), a constant RGB weight, and the Mix Shader factors
    that weigh it per vertex (a tuple of (socket, take, the group nodes the socket lies in): take
    'fac' or '1-fac'), and the Principled
    BSDF node itself where the term is one, else None.  `linked`: {core keyword: socket} of its
    linked inputs that the core takes per vertex (read from textures where the nodes between are
    evaluated); `weight_socket`: a linked colour that weighs the term per vertex (a Glossy BSDF's
    Color), or None."""

    __slots__ = ("inputs", "colour", "factors", "node", "label", "linked", "weight_socket", "outer")

    def __init__(self, inputs, colour, factors, node, label, linked=None, weight_socket=None, outer=WHITE):
        self.inputs = inputs
        self.colour = colour
        self.factors = factors
        self.node = node
        self.label = label
        self.linked = linked or {}
        self.weight_socket = weight_socket
        self.outer = outer  # the constant weight of the mixes above it (colour without the node's own)

    def key(self):
        return ("PRINCIPLED", tuple(sorted(self.inputs.items())))


def _defaults():
    return {row["name"]: row["default"] for row in engine.PRINCIPLED_INPUTS} | {"distribution": "ggx"}


def _value(socket):
    v = socket.default_value
    return tuple(float(c) for c in v[:3]) if hasattr(v, "__len__") else float(v)


def _linked_note(node, sockets):
    linked = [s for s in sockets if node.inputs.get(s) is not None and node.inputs[s].is_linked]
    return [f"'{node.name}': '{s}' is linked: its unlinked value is used" for s in linked]


# The sockets of each BSDF node that the core takes per vertex, by its keyword (the Principled's own
# are textures.TEXTURED_SOCKETS); a Glossy BSDF's Color weighs the term instead
PER_VERTEX_SOCKETS = {
    "ShaderNodeBsdfDiffuse": {"Color": "base_color"},
    "ShaderNodeBsdfGlossy": {"Roughness": "roughness"},
    "ShaderNodeBsdfAnisotropic": {"Roughness": "roughness"},
    "ShaderNodeBsdfMetallic": {"Base Color": "base_color", "Edge Tint": "specular_tint", "Roughness": "roughness"},
    "ShaderNodeBsdfSheen": {"Color": "sheen_tint", "Roughness": "sheen_roughness"},
    "ShaderNodeEmission": {"Color": "emission_color"},
}
WEIGHT_SOCKETS = {"ShaderNodeBsdfGlossy": "Color", "ShaderNodeBsdfAnisotropic": "Color"}


def linked_sockets(node):
    """({core keyword: socket} of a BSDF node's linked inputs the core takes per vertex, the linked
    colour weighing it or None)."""
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        from .textures import TEXTURED_SOCKETS
        table = TEXTURED_SOCKETS
    else:
        table = PER_VERTEX_SOCKETS.get(node.bl_idname, {})
    linked = {kw: node.inputs[sock] for sock, kw in table.items()
              if node.inputs.get(sock) is not None and node.inputs[sock].is_linked}
    weight = WEIGHT_SOCKETS.get(node.bl_idname)
    return linked, (node.inputs[weight] if weight and node.inputs[weight].is_linked else None)


def _unread_note(node, sockets):
    """_linked_note of the sockets the core does not take per vertex."""
    read = set(PER_VERTEX_SOCKETS.get(node.bl_idname, {})) | {WEIGHT_SOCKETS.get(node.bl_idname)}
    return _linked_note(node, [s for s in sockets if s not in read])


def _diffuse(node):
    inputs = _defaults() | {"base_color": _value(node.inputs["Color"]), "specular_ior_level": 0.0,
                            "diffuse_roughness": _value(node.inputs["Roughness"])}
    if compat.DIFFUSE_OREN_NAYAR_CLASSIC:
        inputs["oren_nayar"] = "classic"
    return inputs, WHITE, _unread_note(node, ("Color", "Roughness", "Normal"))


def _distribution(node, allowed=("GGX", "MULTI_GGX")):
    if node.distribution not in allowed:
        return None
    return "multiscatter_ggx" if node.distribution == "MULTI_GGX" else "ggx"


def _glossy(node):
    dist = _distribution(node)
    if dist is None:
        return None, None, [f"'{node.name}': a Glossy BSDF of the {node.distribution.title()} distribution is not "
                            "shaded (GGX and Multiscatter GGX are)"]
    colour = _value(node.inputs["Color"])
    inputs = _defaults() | {"base_color": WHITE, "metallic": 1.0, "specular_tint": WHITE, "distribution": dist,
                            "roughness": _value(node.inputs["Roughness"])}
    notes = _unread_note(node, ("Color", "Roughness", "Anisotropy", "Normal"))
    if node.inputs.get("Anisotropy") is not None and _value(node.inputs["Anisotropy"]) != 0.0:
        notes.append(f"'{node.name}': anisotropy is not shaded")
    if dist == "multiscatter_ggx" and colour != WHITE:
        notes.append(f"'{node.name}': a coloured Multiscatter GGX is shaded with the white lobe's energy "
                     "compensation times its colour (Cycles' is a little darker)")
    # no Fresnel: the colour is a constant factor on the white lobe
    return inputs, tuple(max(c, 0.0) for c in colour), notes


def _metallic(node):
    dist = _distribution(node)
    if dist is None or getattr(node, "fresnel_type", "F82") != "F82":
        return None, None, [f"'{node.name}': a Metallic BSDF other than F82 Tint with GGX is not shaded"]
    inputs = _defaults() | {"base_color": _value(node.inputs["Base Color"]), "metallic": 1.0,
                            "specular_tint": _value(node.inputs["Edge Tint"]), "distribution": dist,
                            "roughness": _value(node.inputs["Roughness"])}
    return inputs, WHITE, _unread_note(node, ("Base Color", "Edge Tint", "Roughness", "Anisotropy", "Normal"))


def _sheen(node):
    if node.distribution != "MICROFIBER":
        return None, None, [f"'{node.name}': a Sheen BSDF of the {node.distribution.title()} distribution is not "
                            "shaded (Microfiber is)"]
    inputs = _defaults() | {"base_color": (0.0, 0.0, 0.0), "specular_ior_level": 0.0, "sheen_weight": 1.0,
                            "sheen_tint": _value(node.inputs["Color"]),
                            "sheen_roughness": _value(node.inputs["Roughness"])}
    return inputs, WHITE, _unread_note(node, ("Color", "Roughness", "Normal"))


def _emission(node):
    inputs = _defaults() | {"base_color": (0.0, 0.0, 0.0), "specular_ior_level": 0.0,
                            "emission_color": _value(node.inputs["Color"]),
                            "emission_strength": _value(node.inputs["Strength"])}
    return inputs, WHITE, _unread_note(node, ("Color", "Strength"))


CLOSURES = {"ShaderNodeBsdfDiffuse": _diffuse, "ShaderNodeBsdfGlossy": _glossy, "ShaderNodeBsdfAnisotropic": _glossy,
            "ShaderNodeBsdfMetallic": _metallic, "ShaderNodeBsdfSheen": _sheen, "ShaderNodeEmission": _emission}


def _source(socket, groups):
    """(node, output socket, groups) feeding a shader socket through reroutes, group outputs (into
    the group's tree) and group inputs (back out to the group node's socket); None when unlinked."""
    for _ in range(MAX_DEPTH):
        if not socket.is_linked:
            return None
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node, out = link.from_node, link.from_socket
        if node.bl_idname == "NodeReroute":
            socket = node.inputs[0]
        elif node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
            inner = next((n for n in node.node_tree.nodes if n.bl_idname == "NodeGroupOutput" and n.is_active_output),
                         None)
            if inner is None:
                return None
            groups = groups + (node,)
            socket = next(s for s in inner.inputs if s.identifier == out.identifier)
        elif node.bl_idname == "NodeGroupInput" and groups:
            outer = groups[-1]
            groups = groups[:-1]
            socket = next(s for s in outer.inputs if s.identifier == out.identifier)
        else:
            return node, out, groups
    return None


def _factor(socket, groups):
    """A Mix Shader's Fac: a number, or the socket to read per vertex (a group's input followed out
    to the socket that feeds it)."""
    for _ in range(MAX_DEPTH):
        fed = nodes.source(socket)
        if fed is None:
            return min(max(float(socket.default_value), 0.0), 1.0), groups
        node, out = fed
        if node.bl_idname == "NodeGroupInput" and groups:
            outer = groups[-1]
            groups = groups[:-1]
            socket = next(s for s in outer.inputs if s.identifier == out.identifier)
            continue
        return socket, groups
    return 0.0, groups


def material_output(material):
    tree = material.node_tree
    if tree is None:
        return None
    out = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    out = [n for n in out if n.is_active_output and n.target in ("ALL", "CYCLES")] or out
    return out[0] if out else None


def terms(material):
    """(terms, notes) of the material's active output's Surface, or (None, notes) when nothing feeds
    it that wenv reads."""
    out = material_output(material)
    if out is None:
        return None, []
    found, notes = [], []

    def walk(socket, colour, factors, groups, depth):
        if depth > MAX_DEPTH:
            notes.append("shader nodes in a cycle (or nested deeper than 64): not read")
            return
        fed = _source(socket, groups)
        if fed is None:
            return
        node, _out, groups = fed
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            from . import materials
            inputs, _ = materials.principled_inputs(node)
            found.append(Term(inputs, colour, factors, node, node.name, *linked_sockets(node)))
        elif kind in CLOSURES:
            inputs, weight, said = CLOSURES[kind](node)
            notes.extend(said)
            if inputs is not None:
                found.append(Term(inputs, tuple(a * b for a, b in zip(colour, weight)), factors, None, node.name,
                                  *linked_sockets(node), outer=colour))
        elif kind == "ShaderNodeMixShader":
            fac, fac_groups = _factor(node.inputs[0], groups)
            shaders = [s for s in node.inputs if s.type == "SHADER"]
            if isinstance(fac, float):
                if fac < 1.0:
                    walk(shaders[0], tuple(c * (1.0 - fac) for c in colour), factors, groups, depth + 1)
                if fac > 0.0:
                    walk(shaders[1], tuple(c * fac for c in colour), factors, groups, depth + 1)
            else:
                walk(shaders[0], colour, factors + ((fac, "1-fac", fac_groups),), groups, depth + 1)
                walk(shaders[1], colour, factors + ((fac, "fac", fac_groups),), groups, depth + 1)
        elif kind == "ShaderNodeAddShader":
            for s in node.inputs:
                walk(s, colour, factors, groups, depth + 1)
        else:
            notes.append(f"'{node.name}' ({node.bl_label}) is not shaded: it adds nothing")

    walk(out.inputs["Surface"], WHITE, (), (), 0)
    return (found or None), notes


def one_principled(found):
    """Whether terms are one Principled BSDF at weight 1: the add-on's Principled model of a single
    node, whose textured inputs are read per vertex."""
    return found is not None and len(found) == 1 and found[0].node is not None and found[0].colour == WHITE and \
        not found[0].factors


def is_one_principled(material):
    return one_principled(terms(material)[0])


def _factor_values(evaluator, factors, rows=False):
    """The product of a term's factors, each read by the evaluator (a textured Fac per vertex), as
    (rows,) float32; a factor wenv does not evaluate reads its unlinked value (named in the notes).
    With `rows` (the mesh's rows read), what only the rows show is raised for the caller to name: a
    missing UV map (MissingUV), a setting that varies or a view's frame (UnreadAtRows)."""
    total = np.ones(evaluator.count, np.float32)
    for socket, take, groups in factors:
        try:
            fac = np.clip(evaluator.value_within(socket, groups), 0.0, 1.0)
        except (nodes.MissingUV, nodes.UnreadAtRows):
            if rows:
                raise
            fac = np.full(evaluator.count, min(max(float(socket.default_value), 0.0), 1.0), np.float32)
        except nodes.Unsupported:
            fac = np.full(evaluator.count, min(max(float(socket.default_value), 0.0), 1.0), np.float32)
        total *= fac if take == "fac" else 1.0 - fac
    return total


def mean_weight(term):
    """A term's weight with each textured factor at its images' means (the glossmeter's reading)."""
    if not term.factors:
        return tuple(float(c) for c in term.colour)
    from .textures import images
    ev = nodes.one_point(lambda node: np.float32([images.mean(node)]))
    f = float(_factor_values(ev, term.factors)[0])
    return tuple(float(c) * f for c in term.colour)


def factor_notes(material):
    """What of the material's textured Mix Shader factors is not evaluated, one sentence each."""
    found, _ = terms(material) if material.node_tree is not None else (None, [])
    notes, seen = [], set()
    for term in found or ():
        for socket, _take, groups in term.factors:
            if socket.as_pointer() in seen:
                continue
            seen.add(socket.as_pointer())
            textures, why = nodes.check(socket, groups)
            if textures is None:
                notes.append(f"'{socket.node.name}''s Fac is linked ({why}): its unlinked value is used")
    return notes
