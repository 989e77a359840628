"""Irradiance normal mapping: bases for directional irradiance over the hemisphere of a surface's normals.

functions.py   SH, Half-Life 2, H-basis, modified H-basis, HSH, Makhotkin and Zernike, by name and count
quadrature.py  integration over the hemisphere and the sphere
projection.py  least-squares projection, reconstruction, the specs' closed forms from nine SH coefficients
irradiance.py  tangent-space directional irradiance from radiance samples and point lights
"""

from arsim.lighting.bases.functions import BASES, Basis, get_basis, parse_basis
from arsim.lighting.bases.projection import gram, project, reconstruct

__all__ = ["BASES", "Basis", "get_basis", "gram", "parse_basis", "project", "reconstruct"]
