"""Geometry import: meshes, implicit prims, curves and points, subdivision surfaces, UsdSkel, PointInstancers, CSG groups and UsdVol volumes."""
