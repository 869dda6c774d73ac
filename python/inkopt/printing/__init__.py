"""Printing: one ink per printer voxel (``quantize``, with blue-noise dither arrays from ``dither``; ``stream``: a
run's mixture quantized one layer at a time), printer output formats with their writers, checkers and registry
(``formats``: PNG slice stacks, GrabCAD Voxel Print packages, volumetric 3MF) and printer profiles (``profiles``:
material slots, resolutions, material names)."""
