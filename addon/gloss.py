"""Glossmeter readings of a material (memoised on its values), and the roughness (a Principled BSDF's)
or alpha (a Cook-Torrance lobe's) for a target gloss."""
from . import engine, materials, textures
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
    """(material_key the glossmeter reads, what it reads of a texture or None): a Principled BSDF
    whose Base Color comes from an Image Texture is read at the texture's mean colour (a reading
    of the whole surface, as an instrument's aperture would average a fine pattern); other linked
    inputs at their unlinked values, which the Material panel names."""
    key = materials.material_key(material.wenv)
    node = materials.principled_node(material) if material.wenv.model == "PRINCIPLED" else None
    source = textures.base_color_source(node)[0] if node is not None else None
    if source is None:
        return key, None
    try:
        mean = textures.images.mean(source.node.image)
    except SetupError as exc:
        return key, f"Base Color's texture cannot be read ({exc}): its unlinked value is read"
    inputs = dict(key[1])
    inputs["base_color"] = tuple(min(max(c, 0.0), 1.0) for c in mean)
    return (key[0], tuple(sorted(inputs.items()))), f"Base Color: the mean of '{source.node.image.name}'"


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
    if node is None:
        raise SetupError(f"'{material.name}' has no Principled BSDF whose Roughness could be set")
    if node.inputs["Roughness"].is_linked:
        raise SetupError("The Principled BSDF's Roughness is linked (a texture or node): set it there")
    inputs = dict(reading_key(material)[0][1])  # a textured Base Color at its mean, as the panel reads it
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
