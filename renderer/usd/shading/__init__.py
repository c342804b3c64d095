"""Material import: UsdShade materials and their networks (UsdPreviewSurface, MaterialX, Arnold's nodes), surface models, MaterialX documents and texture files."""
