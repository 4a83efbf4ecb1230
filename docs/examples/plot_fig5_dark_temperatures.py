"""
Figs. 5: the dark-current map at three temperatures
===================================================

One sensor instance's dark-current histogram at 25, 45 and 65 C, shifted and scaled: each pixel keeps its rank
across temperature, the body and the white-pixel tail move with their own doubling temperatures.
"""

from cmosnoise.app.figures import fig5_dark_temperatures

figure = fig5_dark_temperatures(seed=0)
print(figure.caption)
