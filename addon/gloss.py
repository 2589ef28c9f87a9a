"""Glossmeter readings of a material (memoised on its values), and the roughness (a Principled BSDF's)
or alpha (a Cook-Torrance lobe's) for a target gloss."""
from . import engine, materials
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
    inputs, _ = materials.principled_inputs(node)
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
