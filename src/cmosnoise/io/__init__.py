"""Writing and reading files: layer 4, above the model.

- :mod:`.output`: the output folder (whole or absent: written under a
  temporary name and renamed; ``--overwrite``; a lock; stale temporaries
  restored or removed), JSON with finite numbers, PNG;
- :mod:`.raw_tiff`: raw frames as TIFF with their metadata (and a
  frame-by-frame reader); :mod:`.dng`: DNG; :mod:`.video`: MP4;
- :mod:`.stacks`: measured frames for ``fit`` (a manifest of TIFF, .npy and
  DNG files, or an EMVA 1288 descriptor), reduced frame by frame.

A new output format is a module here, called from :mod:`cmosnoise.app.run`.
"""
