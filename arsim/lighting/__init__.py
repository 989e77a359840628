"""Irradiance and reflection maps from an HDR angle map, by every method of the thesis and faster ones.

accurate.py  brute-force texel sums (Alg. 4.1/4.2) and the bounds optimisation (6.2.2): the reference
sh.py        spherical harmonics: texel-sum coefficients, stable or thesis-faithful Y_lm, synthesis
fast.py      exact maps through SH of the order each Phong lobe needs
mipmap.py    MIP chain and trilinear lookups (eq. 4.1-4.3, Alg. 4.3)
mc.py        Monte Carlo importance sampling with filtered samples
phong.py     the Phong lobe's zonal SH coefficients (eq. 2.33)
methods.py   the methods by name (METHODS), their parameters, and a timed bake
mapset.py    MapSet: one method's maps of one light
"""

_PUBLIC = {
    "METHODS": "arsim.lighting.methods",
    "MapParameters": "arsim.lighting.methods",
    "bake": "arsim.lighting.methods",
    "BakeResult": "arsim.lighting.methods",
    "MapSet": "arsim.lighting.mapset",
    "read_bake": "arsim.lighting.bake_output",
    "write_bake": "arsim.lighting.bake_output",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
