"""USD import: a USD stage to the renderer's plain Scene. pxr is imported here and nowhere else in the renderer."""
