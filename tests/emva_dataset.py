"""Make an EMVA 1288 data set with emva1288's own camera simulator, with what it lacks wrapped around it.

Run as a script (its own interpreter: emva1288 1.0.2 needs NumPy 1 names put back, which no other code should see):

    python tests/emva_dataset.py OUT K FULL_WELL_E OFFSET_SIGMA_E NONLINEARITY DARK_MAP_SIGMA [SEED]

- ``OFFSET_SIGMA_E``: a per-pixel offset map Normal(0, sigma) e- (the simulator's ``dsnu`` image);
- ``NONLINEARITY``: the mean photo-electrons ``u`` become ``u (1 - NL u / full well)`` (compressive, NL at
  saturation), before the simulator's Poisson draw;
- ``DARK_MAP_SIGMA``: the dark current becomes a per-pixel map, lognormal with this log-sigma and mean 1 times
  the simulator's (at 300 e-/s at its reference temperature), growing with exposure as dark current does;
- ``SEED``: another camera and other noise (default 0: the data sets the tests were written on).

200 x 150 pixels, 12 bits, 24 exposure steps, 16-frame stacks, PRNU 1.5 %, dark signal 30 e-, dark noise 3 e-.
Prints the simulator's K (it rounds K to its own grid).
"""

import json
import sys

import numpy as np

for _name, _shim in {"asfarray": lambda a, dtype=float: np.asarray(a, dtype=dtype), "int": int, "float": float}.items():
    hasattr(np, _name) or setattr(np, _name, _shim)

import emva1288.camera.dataset_generator as dg  # noqa: E402
from emva1288.camera import camera as cam_mod  # noqa: E402


def main(out, k, full_well, offset_sigma, nl, dark_sigma, seed=0):
    w, h = 200, 150
    rng = np.random.default_rng(7 + 1000 * seed)
    dark_map = None
    if dark_sigma > 0:
        dark_map = rng.lognormal(0, dark_sigma, (h, w))
        dark_map /= dark_map.mean()

    class Camera(cam_mod.Camera):
        def _u_e(self, radiance, f_number=None):
            u = super()._u_e(radiance, f_number)
            return u * (1 - nl * u / self._u_esat) if nl else u

        def _u_therm(self, temperature=None):
            u = super()._u_therm(temperature)
            return u * dark_map if dark_map is not None and not getattr(self, "_planning", False) else u

        def get_radiance_for(self, *args, **kwargs):  # the generator plans its exposures on the mean dark signal
            self._planning = True
            try:
                return super().get_radiance_for(*args, **kwargs)
            finally:
                self._planning = False

    dg.Cam = Camera
    np.random.seed(1 + 1000 * seed)  # noqa: NPY002 - emva1288's simulator draws from numpy's global generator
    dsnu = rng.normal(0, offset_sigma, (h, w)) if offset_sigma > 0 else None
    prnu = 1 + rng.normal(0, 0.015, (h, w))
    kw = dict(K=k, dark_signal_0=30, sigma2_dark_0=9, u_esat=full_well, dsnu=dsnu, prnu=prnu)
    if dark_map is not None:
        kw["dark_current_ref"] = 300
    g = dg.DatasetGenerator(steps=24, L=16, image_format="tiff", outdir=out, width=w, height=h, bit_depth=12,
                            seed=1 + 1000 * seed, **kw)
    print(json.dumps({"K": float(g.cam.K)}))


if __name__ == "__main__":
    main(sys.argv[1], *(float(a) for a in sys.argv[2:7]), *(int(a) for a in sys.argv[7:8]))
