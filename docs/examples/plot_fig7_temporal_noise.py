"""
Fig. 7: temporal noise per pixel
================================

Each pixel's temporal noise over 100 dark frames against the model: thermal noise plus a Gumbel flicker
sigma with a uniform tail of noisy pixels.
"""

from cmosnoise.app.figures import fig7_temporal_noise

figure = fig7_temporal_noise(seed=0)
print(figure.caption)
