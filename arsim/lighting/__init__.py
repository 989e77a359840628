"""Irradiance and reflection maps from an HDR angle map, by every method of the thesis and faster ones.

accurate.py  brute-force texel sums (Alg. 4.1/4.2) and the bounds optimisation (6.2.2): the reference
sh.py        spherical harmonics: texel-sum coefficients, stable or thesis-faithful Y_lm, synthesis
fast.py      exact maps through SH of the order each Phong lobe needs
mipmap.py    MIP chain and trilinear lookups (eq. 4.1-4.3, Alg. 4.3)
mc.py        Monte Carlo importance sampling with filtered samples
phong.py     the Phong lobe's zonal SH coefficients (eq. 2.33)
methods.py   the methods by name (METHODS), their parameters, and a timed bake
mapset.py    MapSet: one method's maps of one light
ggx.py       GGX prefiltered cube maps and the split sum's BRDF table
export.py    maps for engines (KTX2, Filament's SH, glTF with gltf_ibl.py, faces, equirects)
"""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "methods": ("METHODS", "MapParameters", "bake", "BakeResult"),
    "mapset": ("MapSet",),
    "bake_output": ("read_bake", "write_bake"),
})
