"""Type stub of cmosnoise's lazy public API (``__init__.py`` imports these on first use: a type checker
reads them here). ``tests/test_architecture.py`` holds it to ``__init__``'s tables."""

from . import errors as errors
from ._version import __version__ as __version__
from .analysis import characterize as characterize
from .analysis import colour_error as colour_error
from .analysis import emva as emva
from .analysis import emva_evaluation as emva_evaluation
from .analysis import emva_files as emva_files
from .analysis import figures_of_merit as figures_of_merit
from .analysis import ground_truth as ground_truth
from .analysis import noise_budget as noise_budget
from .analysis import sfr as sfr
from .analysis import snr_light as snr_light
from .analysis import visual_noise as visual_noise
from .analysis import white_pixels as white_pixels
from .app import dataset as dataset
from .app import plots as plots
from .app import sweep as sweep
from .config.loading import load_config as load_config
from .config.loading import merge_updates as merge_updates
from .config.loading import preset_names as preset_names
from .config.schema import Config as Config
from .errors import CmosnoiseError as CmosnoiseError
from .isp import calibration as calibration
from .isp import defects as defect_correction  # noqa: F401  (an alias, re-exported: the tables name it)
from .isp import defects as defects
from .isp import process as process
from .isp import reconstruction as reconstruction
from .isp.process import Processor as Processor
from .model import cfa as cfa
from .model import charts as charts
from .model import distributions as distributions
from .model import fixed_pattern as fixed_pattern
from .model import heavy_tail as heavy_tail
from .model import light as light
from .model import optics as optics
from .model import raw_scene as raw_scene
from .model import scene as scene
from .model import seeds as seeds
from .model import spec as spec
from .model import tiles as tiles
from .model import units as units
from .model.fixed_pattern import FixedPattern as FixedPattern
from .model.fixed_pattern import PatternCache as PatternCache
from .model.raw_info import RawInfo as RawInfo
from .model.sensor import Exposure as Exposure
from .model.sensor import FrameDetail as FrameDetail
from .model.sensor import Sensor as Sensor
from .model.sensor import frames_together as frames_together
from .model.spec import SensorSpec as SensorSpec
from .model.spec import resolve as resolve
from .model.stages import adc as adc
from .model.stages import column_noise as column_noise
from .model.stages import crosstalk as crosstalk
from .model.stages import dark_current as dark_current
from .model.stages import defects as pixel_defects  # noqa: F401  (stage 15 by its physics)
from .model.stages import prnu as prnu
from .model.stages import row_noise as row_noise
from .model.stages import shot_noise as shot_noise
from .model.stages import source_follower as source_follower

__all__: list[str]
