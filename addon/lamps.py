"""The scene's lamps: each Light object that renders, read into the settings the core's wenv.Lamp takes
(Cycles' units and conventions: docs/lamps.md), with a note for each setting Cycles would honour and
wenv does not.  Reads Blender data only; engine.make_lamps makes the core's lamps from the result."""
import math

from . import compat, nodes, world

# Cycles' emission shader when a light has no node tree: Emission of Color 1 and Strength 1
_PLAIN_EMISSION = ((1.0, 1.0, 1.0), 1.0)


def _matrix(obj):
    return tuple(tuple(float(x) for x in row) for row in obj.matrix_world)


def _emission(light, name):
    """The light's node tree's Emission colour and strength, as Cycles multiplies them into the
    light's, and a note when the tree is more than an Emission node whose Color and Strength are
    the same over the light (unlinked, or from nodes of constants: a Blackbody, Value, Math, RGB,
    Mix)."""
    if not getattr(light, "use_nodes", False) or light.node_tree is None:
        return _PLAIN_EMISSION, None
    tree = light.node_tree
    output = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputLight" and n.is_active_output), None)
    surface = output.inputs.get("Surface") if output else None
    node = world.source_node(surface) if surface is not None else None
    if node is None:
        return ((0.0, 0.0, 0.0), 0.0), None  # nothing into its output: Cycles emits nothing
    why = "more than an Emission node"
    if node.bl_idname == "ShaderNodeEmission":
        # (a light's emission is read along the rays that reach it, not a camera's: no Light Path)
        color = nodes.constant_colour(node.inputs["Color"], camera_ray=False)
        strength = nodes.constant_value(node.inputs["Strength"], camera_ray=False)
        if color is not None and strength is not None:
            return (color, strength), None
        why = "what varies over the light or nodes wenv does not evaluate into its Emission node"
    return _PLAIN_EMISSION, (f"Light '{name}': its node tree is not read ({why}): shaded as its colour and power "
                             "alone")


def lamp_settings(obj):
    """The settings of a Light object as wenv.Lamp's keywords (with 'type' and 'matrix'), or None
    when it emits nothing Cycles would shade (a portal); and the notes on what is not honoured."""
    light = obj.data
    notes = []
    cycles = getattr(light, "cycles", None)
    if light.type == "AREA" and cycles is not None and getattr(cycles, "is_portal", False):
        return None, notes  # a portal guides sampling and emits nothing
    (node_color, node_strength), note = _emission(light, obj.name)
    if note:
        notes.append(note)
    color = [c * n for c, n in zip(compat.light_colour(light), node_color)]
    s = {"type": light.type, "matrix": _matrix(obj), "color": tuple(color),
         "energy": float(light.energy) * node_strength, "exposure": compat.light_exposure(light),
         "normalize": compat.light_normalize(light), "cast_shadow": compat.light_cast_shadow(light),
         "diffuse": bool(obj.visible_diffuse), "glossy": bool(obj.visible_glossy)}
    if light.type == "SUN":
        s["angle"] = float(light.angle)
    elif light.type in ("POINT", "SPOT"):
        s["radius"] = float(light.shadow_soft_size)
        s["soft_falloff"] = compat.light_soft_falloff(light)
        if light.type == "SPOT":
            # (its Square setting changes neither Cycles' nor EEVEE's light: the cone is round)
            s["spot_size"], s["spot_blend"] = float(light.spot_size), float(light.spot_blend)
    elif light.type == "AREA":
        s.update(shape=light.shape, size=float(light.size), size_y=float(light.size_y), spread=float(light.spread))
        if s["spread"] < 1e-3:
            notes.append(f"Light '{obj.name}': a spread of {math.degrees(s['spread']):.2g} degrees is a beam, "
                         "not shaded")
            return None, notes
    return s, notes


class Linked:
    """Which objects a Light's linking collection lets in, as Blender's depsgraph reads it: an
    object listed with Include is in, with Exclude out; any other is in unless something is
    included.  `states`: ((object name, 'INCLUDE' or 'EXCLUDE'), ...)."""

    __slots__ = ("states", "includes")

    def __init__(self, states, includes):
        self.states, self.includes = states, includes

    def reaches(self, name):
        state = dict(self.states).get(name)
        return state == "INCLUDE" if state else not self.includes

    def __repr__(self):  # what key_of reads
        return f"Linked({self.states!r}, {self.includes!r})"


def _linked(collection, scene):
    """Linked of a light or shadow linking collection (None: none).  Each object takes the state of
    the entry it is reached through at the collection's first level, an object listed there itself
    after the collections holding it (as the depsgraph visits them)."""
    if collection is None:
        return None
    states = {}
    for child, entry in zip(collection.children, collection.collection_children):
        for obj in child.all_objects:
            states[obj.name] = entry.light_linking.link_state
    for obj, entry in zip(collection.objects, collection.collection_objects):
        states[obj.name] = entry.light_linking.link_state
    here = scene.objects
    includes = any(state == "INCLUDE" and name in here for name, state in states.items())
    return Linked(tuple(sorted(states.items())), includes)


def read_lamps(scene):
    """Every Light object of the scene that renders: (settings for wenv.Lamp, each with its object's
    'name' and its light linking -- 'receivers' and 'blockers', each a Linked or None --; notes).
    Light groups only split Cycles' render passes, whose sum is what is shaded."""
    found, notes = [], []
    for obj in scene.objects:
        links = getattr(obj, "light_linking", None)
        if obj.type == "MESH" and links is not None and (links.receiver_collection or links.blocker_collection):
            notes.append(f"'{obj.name}': an emitting mesh's light linking is not honoured: its light reaches, and "
                         "is blocked by, every object")
        if obj.type != "LIGHT" or obj.hide_render or not obj.visible_get():
            continue
        s, more = lamp_settings(obj)
        notes.extend(more)
        if s is not None:
            s["name"] = obj.name
            s["receivers"] = _linked(links.receiver_collection, scene) if links is not None else None
            s["blockers"] = _linked(links.blocker_collection, scene) if links is not None else None
            found.append(s)
    return found, notes


def lights(settings, name):
    """Whether the lamp of read_lamps' `settings` lights object `name` (its light linking)."""
    return settings["receivers"] is None or settings["receivers"].reaches(name)


def blocked_by(settings, name):
    """Whether object `name` blocks the lamp's light (its shadow linking)."""
    return settings["blockers"] is None or settings["blockers"].reaches(name)


def summary(scene):
    """One line for the panel: the lamps shaded, or None without any."""
    names = [o.name for o in scene.objects if o.type == "LIGHT" and not o.hide_render and o.visible_get()]
    if not names:
        return None
    shown = ", ".join(f"'{n}'" for n in names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return f"{len(names)} lamp(s) shaded as Cycles emits them: {shown}"


def key_of(settings):
    """What tells lamps (read_lamps' settings) from others: a moved lamp or a new power changes it."""
    return tuple(tuple(sorted((k, repr(v)) for k, v in s.items())) for s in settings)


def signature(scene):
    """key_of the scene's lamps as they are now."""
    return key_of(read_lamps(scene)[0])
