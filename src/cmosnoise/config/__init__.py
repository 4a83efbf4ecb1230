"""The configuration layer: schema, loading and merging, presets. No physics.

- :mod:`.schema`: the pydantic sections, one per stage of MODEL.md;
- :mod:`.loading`: defaults <- preset <- file <- overrides, YAML reading;
- :mod:`.messages`: validation errors as one line naming key, value and range;
- ``presets/``: the shipped partial configurations.
"""

from .loading import (
    apply_overrides,
    build_config,
    build_section,
    deep_merge,
    merge_updates,
    parse_override,
    preset_data,
    preset_names,
    read_yaml,
    resolve_config,
)
from .messages import format_validation_error
from .schema import Config, ExposureSection, ProcessingSection

__all__ = [
    "Config", "ExposureSection", "ProcessingSection", "apply_overrides", "build_config", "build_section",
    "deep_merge", "format_validation_error", "merge_updates", "parse_override", "preset_data", "preset_names",
    "read_yaml", "resolve_config",
]
