"""cmosnoise: simulate the noise of CMOS image sensors.

The model follows Gow et al., "A Comprehensive Tool for Modeling CMOS
Image-Sensor-Noise Performance" (IEEE TED 2007), as specified in MODEL.md.
"""

from .config import Config, load_config, preset_names
from .errors import CmosnoiseError
from .pipeline import Exposure, FrameDetail, Sensor

__version__ = "0.1.0"

__all__ = ["Config", "CmosnoiseError", "Exposure", "FrameDetail", "Sensor", "load_config", "preset_names", "__version__"]
