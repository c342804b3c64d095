"""Lights as the kernels see them: the light table, the light shapes' samplers, light sampling with pdfs, the
environment map."""
