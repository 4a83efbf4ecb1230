"""The sensor model of docs/model.md: scenes, the stages, and the sensor that composes them.

- :mod:`.sensor`: :class:`Sensor` (a configuration plus a seed, its fixed
  pattern drawn once) and :class:`Exposure` (one scene's mean charge, frames);
- :mod:`.stages`: one module per stage of the chain, pure functions of arrays;
- :mod:`.scene`, :mod:`.cfa`, :mod:`.units`, :mod:`.distributions`,
  :mod:`.heavy_tail`, :mod:`.seeds`: what the stages are built from;
- :mod:`.physics`: what a configuration implies, checked.
"""
