"""Ray intersection: the time-keyed two-level BVH, its builder, its upload, closest-hit and shadow walks."""
