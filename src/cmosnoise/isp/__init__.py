"""From raw frames to pictures (docs/model.md section 5): layer 5.

- :mod:`.calibration`: black level and dark calibration (master dark);
- :mod:`.defects`: defect correction, by neighbours' median or a defect map;
- :mod:`.reconstruction`: crosstalk compensation, white balance,
  demosaicing, sRGB (and the half-size picture as one compiled pass);
- :mod:`.process`: :class:`~.process.Processor`, composing them.

A new processing step is a module here, composed in :mod:`.process`.
"""
