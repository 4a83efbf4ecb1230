"""
Fig. 9: white pixels and couplets, VGA and 5 MP
===============================================

The same part of the scene on a VGA and a 5 MP sensor, before and after processing: couplets (white pixels
side by side in one colour plane) are circled; the smaller pixels of the 5 MP sensor make more of them.
"""

from cmosnoise.app.figures import fig9_couplets

figure = fig9_couplets(seed=0)
print(figure.caption)
