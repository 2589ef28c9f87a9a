"""Glossmeter readings of a material (memoised on its values), and the roughness (a Principled BSDF's)
or alpha (a Cook-Torrance lobe's) for a target gloss."""
from . import closures, engine, materials, textures
from .engine import SetupError

GEOMETRIES = (20, 60, 85)  # ISO 2813's geometries, degrees

_gloss_memo = {}


def gloss_readings(key):
    """{20: GU, 60: GU, 85: GU, "haze": HU} for a materials.material_key, or a string naming the
    problem (a measured BRDF's missing file among them)."""
    hit = _gloss_memo.get(key)
    if hit is None:
        try:
            hit = dict(zip(GEOMETRIES + ("haze",), engine.gloss(key, GEOMETRIES)))
        except (ValueError, RuntimeError, SetupError) as exc:
            hit = str(exc)
        if len(_gloss_memo) > 256:
            _gloss_memo.clear()
        _gloss_memo[key] = hit
    return hit


def reading_key(material):
    """(material_key the glossmeter reads, what it reads of textures or None): a Principled BSDF whose
    inputs come from Image Textures (through nodes wenv evaluates) is read
    with each texture at its image's mean, the nodes between applied to it (a reading of the whole
    surface, as an instrument's aperture would average a fine pattern); other linked inputs at their
    unlinked values, which the Material panel names."""
    key = materials.material_key(material.wenv)
    if material.wenv.model == "PRINCIPLED" and key[0] == "LAMBERT":
        return key, "no shader node wenv reads: the reading is of a stand-in, Lambertian in the viewport colour"
    if key[0] == "MIXTURE":
        return key, (f"a mix of {len(key[1])} shader nodes: each read apart and summed by its weight (a textured "
                     "Mix Shader factor at its images' mean)")
    node = materials.principled_node(material) if material.wenv.model == "PRINCIPLED" else None
    if node is None:
        return key, None
    inputs, said = dict(key[1]), []
    for socket, keyword in textures.TEXTURED_SOCKETS.items():
        try:
            got = textures.socket_at_means(node, socket)
        except SetupError as exc:
            said.append(f"{socket}'s texture cannot be read ({exc}): its unlinked value is read")
            continue
        if got is None:
            continue
        value, names = got
        # (the core clamps each as Cycles does)
        inputs[keyword] = tuple(float(c) for c in value) if keyword in textures.COLOUR_KEYWORDS else float(value)
        said.append(f"{socket}: the mean of {', '.join(repr(n) for n in names)}")
    if not said:
        return key, None
    return (key[0], tuple(sorted(inputs.items()))), "; ".join(said)


def instrument_geometry(gloss60):
    """The geometry an instrument reports for a 60 degree reading (ISO 2813 rule of thumb)."""
    if gloss60 > 70:
        return 20
    if gloss60 < 10:
        return 85
    return 60


def fit_principled_roughness(material, target, geometry):
    """The Principled BSDF's Roughness (Blender's) reading `target` GU, its other inputs as they are."""
    node = materials.principled_node(material)
    if node is None or not closures.is_one_principled(material):
        raise SetupError(f"'{material.name}' is not one Principled BSDF whose Roughness could be set")
    if node.inputs["Roughness"].is_linked:
        raise SetupError("The Principled BSDF's Roughness is linked (a texture or node): set it there")
    inputs = dict(reading_key(material)[0][1])  # textured inputs at their means, as the panel reads them
    try:
        return engine.fit_principled_roughness(inputs, target, geometry)
    except ValueError as exc:
        raise SetupError(str(exc)) from None


def fit_alpha(settings, target, geometry):
    """The lobe's alpha giving `target` GU for a one-lobe Cook-Torrance material (engine.fit_alpha)."""
    if settings.model != "COOK_TORRANCE" or len(settings.lobes) != 1:
        # a measured BRDF has no roughness to set: it is what was measured
        raise SetupError("Set roughness for a target gloss needs a Cook-Torrance material with exactly one lobe")
    lobe = settings.lobes[0]
    try:
        return engine.fit_alpha(target, geometry=geometry, diffuse=tuple(settings.diffuse),
                                  specular=tuple(lobe.specular), ior=lobe.ior,
                                  distribution=lobe.distribution.lower(), shadowing=settings.shadowing.lower())
    except ValueError as exc:
        raise SetupError(str(exc)) from None
