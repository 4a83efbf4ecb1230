"""
Fig. 6: a body and a tail
=========================

The dark-current distribution as two parts: a lognormal body and a uniform tail of white pixels, solved so
that the configured ppm lies above the threshold.
"""

from cmosnoise.app.figures import fig6_body_and_tail

figure = fig6_body_and_tail(seed=0)
print(figure.caption)
