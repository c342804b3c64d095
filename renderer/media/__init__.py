"""Participating media: volumes (UsdVol fields in sparse grids) and the homogeneous media of closed solids, as the
kernels walk them (``tracking``), with their phase function (``phase``), majorant grids (``grids``) and upload
(``upload``)."""
