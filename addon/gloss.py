"""Glossmeter readings of a material (memoised on its values) and the roughness for a target gloss."""
from . import engine
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


def fit_roughness(settings, target, geometry):
    """Roughness giving `target` GU for a one-lobe Cook-Torrance material (engine.fit_roughness)."""
    if settings.model != "COOK_TORRANCE" or len(settings.lobes) != 1:
        # a measured BRDF has no roughness to set: it is what was measured
        raise SetupError("Set roughness for a target gloss needs a Cook-Torrance material with exactly one lobe")
    lobe = settings.lobes[0]
    try:
        return engine.fit_roughness(target, geometry=geometry, diffuse=tuple(settings.diffuse),
                                  specular=tuple(lobe.specular), ior=lobe.ior,
                                  distribution=lobe.distribution.lower(), shadowing=settings.shadowing.lower())
    except ValueError as exc:
        raise SetupError(str(exc)) from None
