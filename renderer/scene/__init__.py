"""The renderer's own plain scene description (numpy and dataclasses) and the NumPy passes over it."""
