"""Resolving a configuration: defaults <- preset <- file <- extra <- ``--set`` overrides.

Presets are partial configurations shipped in ``cmosnoise/config/presets/``;
they are merged over the defaults. ``--set key.path=value`` overrides are
merged last. Everything here is about data: the result is a validated
:class:`~cmosnoise.config.schema.Config`, with no physics evaluated.
"""

from __future__ import annotations

import copy
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from ..errors import CmosnoiseError
from .messages import format_validation_error
from .schema import Config


def deep_merge(base: dict, override: dict) -> dict:
    """Recursively merge ``override`` into a copy of ``base`` (lists are replaced)."""
    out = copy.deepcopy(base)
    for k, v in override.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse ``a.b.c=value`` (value in YAML syntax) into (["a", "b", "c"], value)."""
    if "=" not in text:
        raise CmosnoiseError(f"--set {text!r}: expected KEY=VALUE, e.g. prnu.sigma_pct=2")
    key, _, raw = text.partition("=")
    key = key.strip()
    if not key or any(not p for p in key.split(".")):
        raise CmosnoiseError(f"--set {text!r}: the key must be a dotted path such as prnu.sigma_pct")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return key.split("."), value


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    out = copy.deepcopy(data)
    for text in overrides:
        path, value = parse_override(text)
        node = out
        for p in path[:-1]:
            nxt = node.get(p)
            if not isinstance(nxt, dict):
                nxt = {}
                node[p] = nxt
            node = nxt
        node[path[-1]] = value
    return out


# ----------------------------------------------------------------- presets
def _preset_dir():
    return resources.files("cmosnoise.config") / "presets"


def preset_names() -> list[str]:
    return sorted(p.name[:-5] for p in _preset_dir().iterdir() if p.name.endswith(".yaml"))


def preset_data(name: str) -> dict:
    path = _preset_dir() / f"{name}.yaml"
    if not path.is_file():
        raise CmosnoiseError(f"unknown preset {name!r}; available: {', '.join(preset_names())}")
    return yaml.safe_load(path.read_text()) or {}


def read_yaml(path: str | Path) -> dict:
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise CmosnoiseError(f"config file {str(p)!r} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CmosnoiseError(f"config file {str(p)!r} cannot be read: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CmosnoiseError(f"config file {str(p)!r} is not valid YAML: {exc}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise CmosnoiseError(f"config file {str(p)!r} must hold a mapping of sections, not {type(data).__name__}")
    return data


def build_section(cls, data: dict, name: str):
    """Validate one section alone (errors name ``name.key``)."""
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        msg = format_validation_error(exc).replace("invalid configuration: ", f"invalid configuration: {name}.")
        raise CmosnoiseError(msg) from None


def build_config(data: dict | None = None) -> Config:
    """Validate a (partial) configuration dict merged over the defaults."""
    try:
        return Config.model_validate(data or {})
    except ValidationError as exc:
        raise CmosnoiseError(format_validation_error(exc)) from None


def resolve_config(
    path: str | Path | None = None,
    preset: str | None = None,
    overrides: list[str] | None = None,
    extra: dict | None = None,
) -> Config:
    """Resolve a configuration: defaults <- preset <- file <- ``extra`` <- ``--set`` overrides.

    Schema-valid only; :func:`cmosnoise.load_config` also checks what the
    values imply (reachable ppm, valid distributions).
    """
    data: dict = {}
    if preset:
        data = deep_merge(data, preset_data(preset))
    if path:
        data = deep_merge(data, read_yaml(path))
    if extra:
        data = deep_merge(data, extra)
    if overrides:
        data = apply_overrides(data, overrides)
    return build_config(data)


def merge_updates(config: Config, updates: dict) -> Config:
    """A new schema-valid configuration: ``config`` with ``updates`` merged in."""
    return build_config(deep_merge(config.to_dict(), updates))
