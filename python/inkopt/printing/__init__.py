"""Printing: one ink per printer voxel and the files a printer takes.

``quantize``: ``quantize(volume, q)`` over one ``model.Quantization``, a pipeline of ``layers`` (the mixture, layer
by layer), ``grid`` (the printer grid and the upsampling registry) and ``dithers`` (one ``Dither`` class per method
in a registry; blue-noise arrays from ``dither``); ``stream``: a run's mixture quantized one layer at a time;
``formats``: the printer output formats, one module each with its writer and checker, in one registry (PNG slice
stacks, GrabCAD Voxel Print packages, volumetric 3MF); ``profiles``: printer profiles (material slots, resolutions,
material names)."""
