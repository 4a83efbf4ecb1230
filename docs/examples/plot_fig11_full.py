"""
Fig. 11: the whole chain
========================

Every noise source switched on with exaggerated values, beside the perfect image.
"""

from cmosnoise.app.figures import fig11_full

figure = fig11_full(seed=0)
print(figure.caption)
