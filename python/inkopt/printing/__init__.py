"""Printing: one ink per printer voxel (``quantize``, with blue-noise dither arrays from ``dither``), printer
input files (``export``: PNG slice stacks; ``gcvf``: GrabCAD Voxel Print packages) and printer profiles
(``profiles``: material slots, resolutions, material names)."""
