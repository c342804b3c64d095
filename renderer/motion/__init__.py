"""Motion over the shutter (the paper's time dimension): transform keys, NumPy and Warp sides."""
