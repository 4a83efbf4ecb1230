"""The chain of docs/model.md section 2, one module per stage, named after its physics.

Each is a set of pure functions of arrays and parameters (and a random
stream) returning arrays, with units and shapes in the docstrings:
``prnu`` (2), ``crosstalk`` (3), ``dark_current`` (4), ``shot_noise`` (5),
``source_follower`` (6), ``row_noise`` (7), ``column_noise`` (8), ``adc`` (9).
"""
