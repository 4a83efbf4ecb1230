"""The EMVA 1288 reference implementation (PyPI ``emva1288``), run in a child process.

emva1288 1.0.2 (2023) still calls ``np.asfarray`` and ``np.int``, which
NumPy 2 removed. Putting them back means patching the ``numpy`` module,
which no other thread of the caller should see; so the reference runs in its
own interpreter (``python -m cmosnoise.analysis.emva_reference DESCRIPTOR``),
where the shim is harmless, and sends its results back as JSON.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ..errors import CmosnoiseError


def reference_results(descriptor: Path, timeout_s: float = 600) -> dict:
    """EMVA 1288 results of a descriptor by the reference implementation, in our quantity names."""
    proc = subprocess.run(
        [sys.executable, "-m", __name__, str(descriptor)], capture_output=True, text=True, timeout=timeout_s
    )
    if proc.returncode == 3:
        raise CmosnoiseError("the EMVA 1288 reference implementation is not installed: pip install emva1288")
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise CmosnoiseError(f"the EMVA 1288 reference implementation failed on {str(descriptor)!r}: {last}")
    return json.loads(proc.stdout)


def _evaluate(descriptor: str) -> dict:
    import logging

    import numpy as np

    for name, shim in {"asfarray": lambda a, dtype=float: np.asarray(a, dtype=dtype), "int": int}.items():
        if not hasattr(np, name):
            setattr(np, name, shim)  # this process only
    from emva1288.process import Data1288, LoadImageData, ParseEmvaDescriptorFile, Results1288

    quiet = logging.WARNING
    parser = ParseEmvaDescriptorFile(descriptor, loglevel=quiet)
    data = Data1288(LoadImageData(parser.images, loglevel=quiet).data, loglevel=quiet)
    r = Results1288(data.data, loglevel=quiet)
    return {
        "system_gain_K_dn_per_e": float(r.K),
        "quantum_efficiency": float(r.QE) / 100,
        "temporal_dark_noise_e": float(r.sigma_d),
        "saturation_capacity_e": float(r.u_e_sat),
        "dark_current_mean_e_per_s": float(r.u_I_mean),
        "dark_current_var_e_per_s": float(r.u_I_var),
        "dsnu_e": float(r.DSNU1288),
        "prnu_pct": float(r.PRNU1288),
        "linearity_error_min_pct": float(r.LE_min),
        "linearity_error_max_pct": float(r.LE_max),
    }


if __name__ == "__main__":
    try:
        import emva1288  # noqa: F401
    except ImportError:
        sys.exit(3)
    import warnings

    warnings.simplefilter("ignore")
    print(json.dumps(_evaluate(sys.argv[1])))
