"""The configuration layer: schema, loading and merging, presets. No physics.

- :mod:`.schema`: the pydantic sections, one per stage of docs/model.md;
- :mod:`.loading`: :func:`load_config` (defaults <- preset <- file <- overrides), :func:`merge_updates`
  (which keeps every value set, None included), YAML reading;
- :mod:`.messages`: validation errors as one line naming key, value and range;
- ``presets/``: the shipped partial configurations.
"""

from .loading import (
    apply_overrides,
    build_section,
    deep_merge,
    load_config,
    merge_updates,
    parse_override,
    preset_data,
    preset_names,
    read_yaml,
)
from .messages import format_validation_error
from .schema import Config, ExposureSection, ProcessingSection

__all__ = [
    "Config", "ExposureSection", "ProcessingSection", "apply_overrides", "build_section",
    "deep_merge", "format_validation_error", "merge_updates", "parse_override", "preset_data", "preset_names",
    "read_yaml", "load_config",
]
