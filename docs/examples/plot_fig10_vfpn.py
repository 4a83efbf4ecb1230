"""
Fig. 10: column fixed-pattern noise
===================================

Six electrons of column offsets (VFPN) at four light levels: the stripes fade as the photon shot noise grows.
"""

from cmosnoise.app.figures import fig10_vfpn

figure = fig10_vfpn(seed=0)
print(figure.caption)
