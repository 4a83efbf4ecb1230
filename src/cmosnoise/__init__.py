"""cmosnoise: simulate the noise of CMOS image sensors.

The model follows Gow et al., "A Comprehensive Tool for Modeling CMOS
Image-Sensor-Noise Performance" (IEEE TED 2007), as specified in
``docs/model.md``.

The public API, imported on first use so that ``import cmosnoise`` stays fast::

    from cmosnoise import Sensor, load_config          # the model (resolve: the SensorSpec a Sensor reads)
    from cmosnoise import Processor                    # raw to picture
    from cmosnoise import white_pixels, noise_budget   # analysis modules

See ARCHITECTURE.md for the layers behind these names.
"""

from __future__ import annotations

import importlib

from ._version import __version__
from .errors import CmosnoiseError

#: public names -> the module that defines them
_NAMES = {
    "Config": "config.schema",
    "preset_names": "config.loading",
    "load_config": "config.loading",
    "merge_updates": "config.loading",
    "SensorSpec": "model.spec",
    "resolve": "model.spec",
    "PatternCache": "model.fixed_pattern",
    "Sensor": "model.sensor",
    "Exposure": "model.sensor",
    "frames_together": "model.sensor",
    "FrameDetail": "model.sensor",
    "FixedPattern": "model.fixed_pattern",
    "RawInfo": "model.raw_info",
    "Processor": "isp.process",
}

#: modules reachable as ``cmosnoise.<name>`` (the stable names of the flat layout)
_MODULES = {
    "scene": "model.scene", "light": "model.light", "optics": "model.optics", "charts": "model.charts",
    "raw_scene": "model.raw_scene", "cfa": "model.cfa", "units": "model.units", "seeds": "model.seeds",
    "distributions": "model.distributions", "heavy_tail": "model.heavy_tail",
    "prnu": "model.stages.prnu", "crosstalk": "model.stages.crosstalk", "dark_current": "model.stages.dark_current",
    "shot_noise": "model.stages.shot_noise", "source_follower": "model.stages.source_follower",
    "row_noise": "model.stages.row_noise", "column_noise": "model.stages.column_noise", "adc": "model.stages.adc",
    # stage 15, the sensor's defective pixels, beside the ISP's correction of them (cmosnoise.defects, the older
    # name, kept; cmosnoise.defect_correction the same module)
    "pixel_defects": "model.stages.defects", "defect_correction": "isp.defects",
    "calibration": "isp.calibration", "defects": "isp.defects", "reconstruction": "isp.reconstruction",
    "process": "isp.process",
    "noise_budget": "analysis.noise_budget", "sfr": "analysis.sfr", "colour_error": "analysis.colour_error",
    "snr_light": "analysis.snr_light", "visual_noise": "analysis.visual_noise", "emva": "analysis.emva", "characterize": "analysis.characterize",
    "white_pixels": "analysis.white_pixels", "figures_of_merit": "analysis.figures_of_merit",
    "emva_evaluation": "analysis.emva_evaluation", "emva_files": "analysis.emva_files",
    "fixed_pattern": "model.fixed_pattern", "spec": "model.spec", "tiles": "model.tiles",
    "plots": "app.plots", "sweep": "app.sweep", "dataset": "app.dataset", "ground_truth": "analysis.ground_truth",
}

__all__ = ["CmosnoiseError", "__version__", *_NAMES, *_MODULES]


def __getattr__(name: str):
    if name in _NAMES:
        value = getattr(importlib.import_module(f".{_NAMES[name]}", __name__), name)
    elif name in _MODULES:
        value = importlib.import_module(f".{_MODULES[name]}", __name__)
    else:
        raise AttributeError(f"module 'cmosnoise' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
