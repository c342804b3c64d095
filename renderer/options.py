"""The names of the render options, without importing Warp (the CLI's client commands list them quickly).

The kernels' integer codes for them live here too, so ``film`` and ``integrator`` use the same tables.
"""
FILTERS = {"box": 0, "triangle": 1, "gaussian": 2, "blackman-harris": 3}  # pixel reconstruction filters
TIME_FILTERS = {"box": 0, "triangle": 1, "strobe": 2}  # shutter weightings
AOV_NAMES = ("depth", "normal", "albedo")
MAX_DEPTH = 64
