"""Printing: one ink per printer voxel (``quantize``, with blue-noise dither arrays from ``dither``), printer
input files (``export``: PNG slice stacks) and printer profiles (``profiles``)."""
