"""Surface scattering: the UsdPreviewSurface BSDF, its lobes and microfacet pieces, materials, textures."""
