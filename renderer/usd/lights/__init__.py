"""Light import: UsdLux lights, MeshLightAPI lights, light and shadow linking, light groups."""
