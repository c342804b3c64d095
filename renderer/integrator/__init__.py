"""The integrator: the path tracing kernel (``path``, and its variant with compositing layers, ``layers``) and the
render loop that drives it over a tile in waves of samples (``tile``) and over a frame on threads (``frame``)."""
