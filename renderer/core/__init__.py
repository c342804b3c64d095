"""Small services every part of the renderer uses: colour management (``color``) and atomic file writes
(``files``)."""
