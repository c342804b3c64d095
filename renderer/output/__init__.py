"""What a render writes: a frame's EXR channels and header (``frame``), RenderVars as layers of products
(``var_channels``), tile checkpoints (``checkpoint``)."""
