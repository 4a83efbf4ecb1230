"""
Fig. 3: photo-response non-uniformity
=====================================

Ten per cent PRNU on a 14 x 14 monochrome flat field of 1000 e-: the pixel-to-pixel spread of the response,
nothing else switched on.
"""

from cmosnoise.app.figures import fig3_prnu

figure = fig3_prnu(seed=0)
print(figure.caption)
