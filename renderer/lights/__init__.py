"""Lights as the kernels see them: the light table, light sampling with pdfs, the environment map."""
