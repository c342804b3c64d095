"""The camera: the thin lens moving over the shutter (``lens``) and which pixels of which frame an image holds
(``framing``)."""
