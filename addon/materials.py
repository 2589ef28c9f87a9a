"""Materials: the key a core material is built from -- the Principled BSDF node read as it is, or the
add-on's own Cook-Torrance, Lambert or measured settings -- what of a material wenv does not shade,
and the conversion of Principled BSDF values into Cook-Torrance lobes."""
import math

import bpy

from . import closures, engine, nodes


def _unit(x):
    """x clamped to [0, 1], as Cycles clamps a colour channel or a weight."""
    return min(max(float(x), 0.0), 1.0)


def brdf_file(settings):
    """The absolute path of a measured material's BRDF file: a path starting with // is relative to
    the .blend (or to the library the material comes from), as every file path in Blender."""
    material = settings.id_data
    return bpy.path.abspath(settings.brdf_path, library=getattr(material, "library", None))


# The Principled BSDF node's sockets by wenv.Principled's names, from the core's one list of them
# (the ones a Blender version lacks -- Diffuse Roughness before 4.3, Thin Film before 4.2 -- keep
# wenv's defaults, which are Blender's).
PRINCIPLED_SOCKETS = {row["name"]: row["socket"] for row in engine.PRINCIPLED_INPUTS}
# Inputs that shape the surface rather than its reflectance: wenv shades the mesh's own normals.
GEOMETRY_SOCKETS = ("Normal", "Coat Normal", "Tangent")
# What wenv does not shade of a Principled BSDF (wenv.Principled.unhonoured's names), in words.
NOT_SHADED = {row["name"]: row["note"] for row in engine.PRINCIPLED_INPUTS if row["note"]}


def principled_inputs(node):
    """({wenv name: value} of a Principled BSDF node's unlinked values and its distribution, [names of
    its linked sockets])."""
    inputs, linked = {}, []
    for row in engine.PRINCIPLED_INPUTS:
        name, socket_name = row["name"], row["socket"]
        sock = node.inputs.get(socket_name)
        if sock is None:  # a socket this Blender lacks: the node's default in the versions that have it
            inputs[name] = row["default"]
            continue
        if sock.is_linked:
            linked.append(socket_name)
        value = sock.default_value
        inputs[name] = tuple(float(c) for c in value[:3]) if hasattr(value, "__len__") else float(value)
    inputs["distribution"] = "multiscatter_ggx" if node.distribution == "MULTI_GGX" else "ggx"
    linked += [s for s in GEOMETRY_SOCKETS if node.inputs.get(s) is not None and node.inputs[s].is_linked]
    return inputs, linked


def material_key(settings):
    """Plain tuple of every value the wenv material depends on (for caches and the live mode);
    engine.material_from_key turns it into a core material.  A Principled material's key holds the
    node's values as they are now (the node is the source of truth: nothing is copied), a measured
    one's its file's size and modification time, so a changed file is read again."""
    if settings is None:
        return ("default",)
    if settings.model == "PRINCIPLED":
        found, _ = closures.terms(settings.id_data) if settings.id_data.node_tree is not None else (None, [])
        if found is None:  # no shader node wenv reads: Lambertian with the viewport colour
            return ("LAMBERT", tuple(_unit(c) for c in settings.id_data.diffuse_color[:3]), "SMITH", ())
        if closures.one_principled(found):
            return found[0].key()
        # the mean weight stands for a textured factor here (the glossmeter's reading): the shading
        # reads each vertex's (closures.vertex_weights)
        return ("MIXTURE", tuple((t.key(), closures.mean_weight(t)) for t in found))
    if settings.model == "MEASURED":
        return ("MEASURED", settings.brdf_path, engine.file_signature(brdf_file(settings)))
    lobes = tuple((tuple(l.specular), l.alpha, l.ior, l.distribution) for l in settings.lobes)
    return (settings.model, tuple(settings.diffuse), settings.shadowing, lobes)


def _ior_for_reflectance(f0):
    """Dielectric index whose normal-incidence Fresnel reflectance is f0 (capped at the core's max)."""
    s = math.sqrt(min(max(f0, 1e-4), 0.99))
    return min((1 + s) / (1 - s), engine.IOR_RANGE[1])


def _fresnel0(n):
    return ((n - 1) / (n + 1)) ** 2


# What principled_lobes lets its lobes reflect together: all of it (the core allows 1 % more, its
# quadrature's margin; a single lobe coloured at most 1 stays under 1 and is left alone).
ENERGY_LIMIT = 1.0


def principled_lobes(base, metallic, roughness, ior, spec_level=0.5, spec_tint=(1, 1, 1),
                     coat=0.0, coat_roughness=0.03, coat_ior=1.5):
    """wenv settings (diffuse, lobes) for Principled BSDF values.  See docs/addon.md, "Cook-Torrance
    from Principled BSDF".

    - roughness r -> GGX alpha r^2 (as Cycles), floored (engine.alpha_from_roughness);
    - dielectric part (weight 1 - metallic): diffuse = base colour, one GGX lobe of index IOR,
      scaled by Specular Tint and 2 x Specular IOR Level (0.5 keeps Fresnel unchanged);
    - metallic part: a GGX lobe coloured base / F0(n_m) with n_m the index whose normal-incidence
      reflectance is the brightest base channel, so it reflects the base colour head-on and rises
      towards grazing like a conductor;
    - Coat Weight > 0 adds a clear lobe (Coat Roughness^2, Coat IOR) on top;
    - Cook-Torrance adds its lobes where Cycles layers them (a coat dims what lies under it), so
      where their sum would reflect more than the surface receives at the views the core checks
      (0 to 75 degrees) every lobe is scaled down until it reflects at most that (the core
      refuses more).
    """
    # clamped as Cycles clamps the node's inputs (a script may set a socket past its range)
    base = [_unit(c) for c in base[:3]]
    t = _unit(metallic)
    alpha = engine.alpha_from_roughness(_unit(roughness))
    spec_level = max(float(spec_level), 0.0)
    spec_tint = [max(float(c), 0.0) for c in spec_tint[:3]]
    ior = engine.clamp_ior(ior)
    diffuse = tuple(c * (1 - t) for c in base)
    lobes = []
    if t < 1:
        scale = (1 - t) * 2 * float(spec_level)
        if scale > 0:
            lobes.append({"specular": tuple(scale * float(c) for c in spec_tint[:3]), "alpha": alpha,
                          "ior": ior, "distribution": "GGX"})
    if t > 0:
        n_m = _ior_for_reflectance(max(base))
        f0 = _fresnel0(n_m)
        lobes.append({"specular": tuple(t * c / f0 for c in base), "alpha": alpha, "ior": n_m,
                      "distribution": "GGX"})
    if coat > 0:
        lobes.append({"specular": (float(coat),) * 3, "alpha": engine.alpha_from_roughness(_unit(coat_roughness)),
                      "ior": engine.clamp_ior(coat_ior), "distribution": "GGX"})
    peak = engine.lobes_peak_albedo(lobes)
    if peak > ENERGY_LIMIT:
        for lobe in lobes:
            lobe["specular"] = tuple(c * ENERGY_LIMIT / peak for c in lobe["specular"])
    return diffuse, lobes


def principled_node(material):
    """The material's Principled BSDF whose inputs are read (its textures, its normal map, the
    roughness the glossmeter sets): the one its output shows alone (in a node group too), else the
    first in its tree."""
    tree = material.node_tree
    if tree is None:
        return None
    found, _ = closures.terms(material)
    if found is not None and len(found) == 1 and found[0].node is not None:
        return found[0].node
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None)


def fill_from_principled(material):
    """Sets material.wenv from its Principled BSDF (or, without one, from the viewport colour,
    Lambertian).  Returns a list of warnings for the user."""
    warnings = []
    st = material.wenv
    node = principled_node(material)
    if node is None:
        st.model = "LAMBERT"
        st.diffuse = tuple(material.diffuse_color[:3])
        st.lobes.clear()
        warnings.append(f"'{material.name}' has no Principled BSDF: Lambertian with its viewport colour")
        st.initialized = True
        return warnings
    v, linked = principled_inputs(node)
    used = ("base_color", "metallic", "roughness", "ior", "specular_ior_level", "specular_tint", "coat_weight",
            "coat_roughness", "coat_ior")
    warnings += [f"'{PRINCIPLED_SOCKETS[name]}' is linked; its unlinked value was used" for name in used
                 if PRINCIPLED_SOCKETS[name] in linked]
    for name in used:
        values = v[name] if isinstance(v[name], tuple) else (v[name],)
        if not all(math.isfinite(x) for x in values):
            raise engine.SetupError(f"'{material.name}': the Principled BSDF's {PRINCIPLED_SOCKETS[name]} is not "
                                    "finite")
    diffuse, lobes = principled_lobes(v["base_color"], v["metallic"], v["roughness"], v["ior"],
                                      spec_level=v["specular_ior_level"], spec_tint=v["specular_tint"],
                                      coat=v["coat_weight"], coat_roughness=v["coat_roughness"],
                                      coat_ior=v["coat_ior"])
    st.model = "COOK_TORRANCE"
    st.shadowing = "SMITH"
    st.diffuse = diffuse
    st.lobes.clear()
    for lobe in lobes:
        item = st.lobes.add()
        item.specular = lobe["specular"]
        item.alpha = lobe["alpha"]
        item.ior = lobe["ior"]
        item.distribution = lobe["distribution"]
    st.active_lobe = 0
    st.initialized = True
    return warnings


def ensure_material_settings(material):
    """A Cook-Torrance material never set up takes its lobes from its Principled BSDF (materials set to
    the Principled model read the node itself at every pass)."""
    if material is not None and material.wenv.model == "COOK_TORRANCE" and not material.wenv.initialized:
        return fill_from_principled(material)
    return []


def _value_text(value):
    if isinstance(value, tuple):
        return "(" + ", ".join(f"{c:.3g}" for c in value) + ")"
    return f"{value:.3g}"


def _textured_sockets():
    from . import textures  # (textures reads this module's principled_node)
    return textures.TEXTURED_SOCKETS


def _socket_textures(node, socket):
    from . import textures
    return textures.socket_textures(node, socket)


def _normal_source(node):
    from . import textures
    return textures.normal_source(node)


def _term_notes(found):
    """What of a mixture's terms' linked inputs is read otherwise than Cycles reads it: an input the
    core takes per vertex whose nodes are not evaluated, and a Principled BSDF's other linked inputs
    (its unlinked values are used; a normal map in a mixture is not read)."""
    notes = []
    for term in found:
        sockets = list(term.linked.values()) + ([term.weight_socket] if term.weight_socket is not None else [])
        for socket in sockets:
            read, said = nodes.check(socket)
            notes += said if read is not None else [
                f"'{term.label}': '{socket.name}' is linked ({said}): its unlinked value is used"]
        if term.node is not None:
            other = [s for s in PRINCIPLED_SOCKETS.values() if s not in _textured_sockets() and
                     term.node.inputs.get(s) is not None and term.node.inputs[s].is_linked]
            other += [s for s in GEOMETRY_SOCKETS if term.node.inputs.get(s) is not None and term.node.inputs[s].is_linked]
            notes += [f"'{term.label}': '{s}' is linked: its unlinked value is used" if s not in GEOMETRY_SOCKETS else
                      f"'{term.label}': '{s}' is linked: a BSDF mixed with others is shaded with the mesh's normals"
                      for s in other]
    return notes


def principled_notes(material):
    """What wenv does not shade of the material as it is set up now, one sentence each: for the
    Principled model, linked inputs (textures: their unlinked value is used; normal maps), inputs
    wenv does not shade, a node tree with more than the Principled BSDF; no notes for the add-on's
    own models."""
    if material is None or material.wenv.model != "PRINCIPLED":
        return []
    found, closure_notes = closures.terms(material) if material.node_tree is not None else (None, [])
    if found is None:
        return closure_notes + ["no shader node wenv reads: shaded as Lambertian with its viewport colour"]
    if not closures.one_principled(found):
        return closure_notes + closures.factor_notes(material) + _term_notes(found)
    node = principled_node(material)
    notes = []
    inputs, linked = principled_inputs(node)
    by_socket = {socket: name for name, socket in PRINCIPLED_SOCKETS.items()}
    for socket in linked:
        if socket == "Normal":
            chain, why = _normal_source(node)
            notes.append(chain.note() if chain is not None else
                         f"'Normal' is linked ({why}): not used, the mesh's normals are")
        elif socket in GEOMETRY_SOCKETS:
            notes.append(f"'{socket}' is linked (a normal or bump map): not used, the mesh's normals are")
        elif socket in _textured_sockets():
            read, said = _socket_textures(node, socket)
            if read is not None:
                notes += said  # read at the vertices: what of it is read otherwise than Cycles reads it
                partly = NOT_SHADED.get(by_socket[socket])  # what of the input is not shaded, at any value
                if partly and partly not in notes:
                    notes.append(partly)
            else:
                value = _value_text(inputs[by_socket[socket]])
                notes.append(f"'{socket}' is linked ({said}): its unlinked value {value} is used")
        else:
            value = inputs[by_socket[socket]]
            notes.append(f"'{socket}' is linked (a texture or node): its unlinked value {_value_text(value)} is used")
    try:
        notes += [NOT_SHADED[name] for name in engine.principled_unhonoured(inputs) if NOT_SHADED[name] not in notes]
    except ValueError as exc:  # a value the core refuses (NaN, or past what it can shade)
        notes.append(f"cannot be shaded: {exc}")
    return closure_notes + notes


def slot_notes(obj):
    """principled_notes of obj's materials, each prefixed with the material's name."""
    notes = []
    for slot in obj.material_slots:
        if slot.material is not None:
            notes += [f"'{slot.material.name}': {n}" for n in principled_notes(slot.material)]
    return notes


def slot_material_keys(obj):
    """material_key of each of obj's material slots (filled from the Principled BSDF on first use).
    Each is made here, on the main thread, so a missing or broken measured BRDF file, or lobes
    the core refuses (reflecting more than they receive), are a SetupError naming the material
    before any shading starts."""
    return material_keys([slot.material for slot in obj.material_slots])


def material_keys(mats):
    """slot_material_keys of the materials of an object's slots (None: an empty slot)."""
    keys = []
    for mat in mats:
        ensure_material_settings(mat)
        key = material_key(mat.wenv if mat is not None else None)
        if key[0] != "default":
            try:
                for term in engine.term_keys(key):
                    engine.material_from_key(term)
            except (engine.SetupError, ValueError) as exc:
                raise engine.SetupError(f"Material '{mat.name}': {exc}") from None
        keys.append(key)
    return keys or [("default",)]
