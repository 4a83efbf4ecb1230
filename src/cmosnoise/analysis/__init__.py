"""Measurements, figures of merit and fits: layer 6.

- :mod:`.figures_of_merit`: the one estimator of each figure (temporal
  noise, key figures, dark current and white pixels) that ``simulate``'s
  summary, the sweep, the explorer and the report use;
- :mod:`.noise_budget`: each noise source's share, with clipping;
- :mod:`.white_pixels`: white pixels and couplets; :mod:`.run_stats`:
  statistics gathered frame by frame;
- :mod:`.emva`, :mod:`.characterize`, :mod:`.emva_reference`: EMVA 1288
  characterization (measurement, evaluation, and the reference
  implementation where it is installed);
- :mod:`.fit`, composing :mod:`.fit_dark`, :mod:`.fit_readout` and
  :mod:`.fit_photo`: every stage fitted to a measured data set.

A new measurement or figure of merit goes here (a figure reported by
several commands into :mod:`.figures_of_merit`).
"""
