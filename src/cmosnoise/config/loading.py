"""Resolving a configuration: defaults <- preset <- file <- extra <- ``--set`` overrides.

Presets are partial configurations shipped in ``cmosnoise/config/presets/``;
they are merged over the defaults. ``--set key.path=value`` overrides are
merged last. Everything here is about data: the result is a validated
:class:`~cmosnoise.config.schema.Config`, with no physics evaluated.
"""

from __future__ import annotations

import copy
import functools
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from .. import inputs
from ..errors import CmosnoiseError
from .messages import format_validation_error
from .schema import Config


def deep_merge(base: dict, override: dict) -> dict:
    """Recursively merge ``override`` into a copy of ``base`` (lists are replaced)."""
    out = copy.deepcopy(base)
    _merge_into(out, override)
    return out


def _merge_into(out: dict, override: dict) -> None:
    """:func:`deep_merge`'s work on ``out``, a copy already (each level copied once, not once per depth)."""
    for k, v in override.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            _merge_into(out[k], v)
        else:
            out[k] = copy.deepcopy(v)


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse ``a.b.c=value`` (value in YAML syntax) into (["a", "b", "c"], value)."""
    shown = text if len(text) <= 120 else f"{text[:100]}...({len(text)} characters)"
    if "=" not in text:
        raise CmosnoiseError(f"--set {shown!r}: expected KEY=VALUE, e.g. prnu.sigma_pct=2")
    key, _, raw = text.partition("=")
    key = key.strip()
    if not key or any(not p for p in key.split(".")):
        raise CmosnoiseError(f"--set {shown!r}: the key must be a dotted path such as prnu.sigma_pct")
    try:
        value = load_yaml_text(raw) if raw.strip() else None
    except yaml.constructor.ConstructorError as exc:
        raise CmosnoiseError(f"--set {shown!r}: {exc.problem}") from None
    except yaml.YAMLError:
        value = raw
    return key.split("."), value


def apply_overrides(data: dict, overrides: list[str], defaults: dict | None = None) -> dict:
    """``data`` with each ``a.b.c=value`` applied; a number in the path indexes a list (``points.0.mean_e_per_s=5``).

    A list the data do not hold yet is taken from ``defaults`` (the schema's
    defaults) first, so ``--set dark_current.points.1.std_e_per_s=3`` edits
    the second default point. An index may also be the list's length, which
    appends an item.
    """
    out = copy.deepcopy(data)
    for text in overrides:
        path, value = parse_override(text)
        _apply(out, path, value, defaults, f"--set {text!r}")
    return out


def apply_values(data: dict, values: dict[str, Any], defaults: dict | None = None, where: str = "--vary") -> dict:
    """``data`` with each dotted key of ``values`` set, as :func:`apply_overrides` does (list items by their index:
    ``dark_current.points.0.tail.ppm_above``); ``where`` names the option in errors."""
    out = copy.deepcopy(data)
    for key, value in values.items():
        path = key.split(".")
        if any(not p for p in path):
            raise CmosnoiseError(f"{where} {key!r}: the key must be a dotted path such as prnu.sigma_pct")
        _apply(out, path, copy.deepcopy(value), defaults, f"{where} {key}")
    return out


def _apply(out: dict, path: list[str], value: Any, defaults: dict | None, text: str) -> None:
    node: Any = out  # a mapping, or a list where the path names an item
    default = defaults
    for i, p in enumerate(path):
        last = i == len(path) - 1
        key: Any = _index(node, p, text, path[: i + 1]) if isinstance(node, list) else p
        if default is not None:
            try:
                default = default[key]
            except (KeyError, IndexError, TypeError):
                default = None
        if last:
            if isinstance(node, list) and key == len(node):
                node.append(value)
            else:
                node[key] = value
            return
        nxt = node[key] if (isinstance(node, dict) and key in node) or (isinstance(node, list) and key < len(node)) else None
        if not isinstance(nxt, (dict, list)):
            nxt = copy.deepcopy(default) if isinstance(default, list) else {}  # only lists: a dict stays sparse
            if isinstance(node, list) and key == len(node):
                node.append(nxt)
            else:
                node[key] = nxt
        node = nxt


def _index(node: list, part: str, text: str, path: list[str]) -> int:
    try:
        k = int(part)
    except ValueError:
        raise CmosnoiseError(f"{text}: {'.'.join(path[:-1])} is a list; index it with a number, e.g. "
                             f"{'.'.join(path[:-1])}.0") from None
    if not 0 <= k <= len(node):
        raise CmosnoiseError(f"{text}: {'.'.join(path[:-1])} has {len(node)} item(s); "
                             f"use an index from 0 to {len(node) - 1} (or {len(node)} to append)")
    return k


# ----------------------------------------------------------------- presets
def _preset_dir():
    return resources.files("cmosnoise.config") / "presets"


def preset_names() -> list[str]:
    """The shipped presets' names, sorted.

    Returns
    -------
    list of str
        Each a name ``load_config(preset=...)`` and ``--preset`` take.

    Examples
    --------
    >>> from cmosnoise import preset_names
    >>> "paper-fig9-vga" in preset_names()
    True
    """
    return sorted(p.name[:-5] for p in _preset_dir().iterdir() if p.name.endswith(".yaml"))


def preset_data(name: str) -> dict:
    """A shipped preset's data, by name alone (a path is no preset: ``--config`` reads a file), read with the
    same strict loader as a configuration file."""
    if not isinstance(name, str) or name not in preset_names():
        raise CmosnoiseError(f"unknown preset {name!r}; available: {', '.join(preset_names())}"
                             + (" (a configuration file is given with --config)" if isinstance(name, str)
                                and ("/" in name or "\\" in name or name.endswith((".yaml", ".yml"))) else ""))
    return load_yaml_text((_preset_dir() / f"{name}.yaml").read_text()) or {}


#: a configuration file is at most this large (bytes) and this deeply nested
MAX_CONFIG_BYTES = 1_000_000
MAX_NESTING = 32
#: digits of one number in a configuration (a seed is at most 20; Python refuses to read past 4300)
MAX_NUMBER_DIGITS = 100


class _StrictLoader(yaml.SafeLoader):
    """Safe YAML without aliases (no "billion laughs") and at most MAX_NESTING levels deep."""

    _depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not accepted in a configuration",
                                              self.peek_event().start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_NESTING:
                raise yaml.composer.ComposerError(None, None, f"nested more than {MAX_NESTING} levels deep",
                                                  self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        """A mapping whose keys are each given once: a repeated key would keep its last value without a word."""
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:  # an unhashable key: the base constructor says so
                    continue
                if first is not key_node:
                    raise yaml.constructor.ConstructorError(
                        "while reading a mapping", node.start_mark,
                        f"the key {key!r} is given twice (first {first.start_mark.line + 1}:"
                        f"{first.start_mark.column + 1}); give each key once", key_node.start_mark)
        return super().construct_mapping(node, deep)


def _strict_number(kind: str):
    """YAML 1.1 reads ``1:2`` as 62 (base 60) and ``010`` as 8 (octal): refused as numbers, with the reason."""
    base = yaml.SafeLoader.construct_yaml_int if kind == "int" else yaml.SafeLoader.construct_yaml_float

    def construct(loader, node):
        text = str(node.value).replace("_", "")
        digits = text.lstrip("+-")
        if ":" in text:
            raise yaml.constructor.ConstructorError(None, None, f"{node.value!r} would be read as a base-60 number; "
                                                    "write the number itself (or quote it as text)", node.start_mark)
        if kind == "int" and len(digits) > 1 and digits[0] == "0" and digits[1:].isdigit():
            raise yaml.constructor.ConstructorError(None, None, f"{node.value!r} would be read as an octal number; "
                                                    "write it without the leading zero", node.start_mark)
        if kind == "int" and digits[:2].lower() in ("0b", "0x", "0o"):
            base_name = {"0b": "binary", "0x": "hexadecimal", "0o": "octal"}[digits[:2].lower()]
            raise yaml.constructor.ConstructorError(None, None, f"{node.value!r} would be read as a {base_name} "
                                                    "number; write the number in decimal", node.start_mark)
        if len(digits) > MAX_NUMBER_DIGITS:
            raise yaml.constructor.ConstructorError(None, None, f"a number of {len(digits)} digits; at most "
                                                    f"{MAX_NUMBER_DIGITS} are read", node.start_mark)
        return base(loader, node)

    return construct


_StrictLoader.add_constructor("tag:yaml.org,2002:int", _strict_number("int"))
_StrictLoader.add_constructor("tag:yaml.org,2002:float", _strict_number("float"))


def load_yaml_text(text: str):
    """YAML text to data with :class:`_StrictLoader` (the same rules for files and ``--set`` values)."""
    return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass


def read_yaml(path: str | Path) -> dict:
    """A configuration file: a regular file of at most MAX_CONFIG_BYTES, strict YAML, a mapping."""
    p = Path(path)
    return config_data(inputs.read_text(p, "config file", MAX_CONFIG_BYTES), f"config file {str(p)!r}")


def config_data(text: str, where: str) -> dict:
    """A configuration file's text as data: strict YAML, a mapping of sections (``{}`` for an empty text);
    ``where`` names the file in the one-line error."""
    try:
        data = load_yaml_text(text)
    except yaml.YAMLError as exc:
        raise CmosnoiseError(f"{where} is not valid YAML: {' '.join(str(exc).split())[:300]}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise CmosnoiseError(f"{where} must hold a mapping of sections, not {type(data).__name__}")
    return data


def build_section(cls, data: dict, name: str):
    """Validate one section alone (errors name ``name.key``)."""
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        msg = format_validation_error(exc).replace("invalid configuration: ", f"invalid configuration: {name}.")
        raise CmosnoiseError(msg) from None


def validate_data(data: dict | None = None) -> Config:
    """Validate a (partial) configuration dict merged over the defaults."""
    try:
        return Config.model_validate(data or {})
    except ValidationError as exc:
        raise CmosnoiseError(format_validation_error(exc)) from None


def load_config(
    path: str | Path | None = None,
    preset: str | None = None,
    overrides: list[str] | None = None,
    extra: dict | None = None,
    notes: list | None = None,
) -> Config:
    """A configuration: defaults <- preset <- file <- ``extra`` <- ``--set`` overrides, validated.

    Parameters
    ----------
    path : str or Path, optional
        A YAML configuration file (a mapping of sections; any key left out keeps its default).
    preset : str, optional
        A shipped preset (:func:`preset_names`), merged under the file.
    overrides : list of str, optional
        ``--set`` strings, ``key.path=value`` in YAML syntax, applied last (a number indexes a list).
    extra : dict, optional
        A (partial) configuration as data, merged over the file.
    notes : list, optional
        Told, one line each, what the file, ``extra`` and the overrides set that the configuration does not use
        (:func:`inactive_notes`; light in lux is switched on where an illuminance was given without it).

    Returns
    -------
    Config
        Schema-valid. What the values imply (reachable ppm, computable
        distributions, PRNU solved from its measured value) is resolved by
        :func:`cmosnoise.model.spec.resolve`, which :class:`~cmosnoise.Sensor` calls.

    Examples
    --------
    >>> from cmosnoise import load_config
    >>> config = load_config(preset="paper-fig9-vga", overrides=["sensor.temperature_c=45"])
    >>> config.sensor.width, config.sensor.temperature_c
    (640, 45.0)
    """
    data: dict = {}
    given: dict = {}  # what the file, extra and --set gave: the user's keys, not the preset's
    if preset:
        data = deep_merge(data, preset_data(preset))
    if path:
        file_data = read_yaml(path)
        data, given = deep_merge(data, file_data), deep_merge(given, file_data)
    if extra:
        data, given = deep_merge(data, extra), deep_merge(given, extra)
    if overrides:
        data = apply_overrides(data, overrides, default_data())
        given = apply_overrides(given, overrides, default_data())
    said = inactive_notes(data, given)
    if notes is not None:
        notes.extend(said)
    return validate_data(data)


#: the sections (dotted) whose ``enabled`` switches their other keys on or off
_SWITCHED = ("light", "prnu", "crosstalk", "dark_current", "dark_current.rts", "shot_noise", "source_follower",
             "source_follower.flicker", "source_follower.rts", "row_noise", "column_noise", "column_noise.temporal",
             "adc", "pixel_offset", "nonlinearity", "read_noise", "defects")


def inactive_notes(data: dict, given: dict) -> list[str]:
    """What ``given`` (the user's keys) sets that ``data`` does not use, one line each; ``data`` changed where the
    intent is unambiguous.

    - A key of a section whose ``enabled`` is false (and not set by ``given``): light in lux is switched on where
      ``light.illuminance_lux`` or ``light.luminance_cd_m2`` is given (``data`` changed, said so); any other
      section's keys are said to have no effect.
    - ``sensor.pixel_pitch_um`` given while the dark current is per pixel (no point in nA/cm^2): it stays as it was.

    Parameters
    ----------
    data : dict
        The whole configuration's data (defaults not in it).
    given : dict
        The part of it the user gave.

    Returns
    -------
    list of str
    """
    defaults = default_data()
    out = []

    def node(d, dotted):
        for part in dotted.split("."):
            d = d.get(part) if isinstance(d, dict) else None
        return d

    for dotted in _SWITCHED:
        mine = node(given, dotted)
        if not isinstance(mine, dict) or "enabled" in mine:
            continue
        keys = sorted(k for k in mine if f"{dotted}.{k}" not in _SWITCHED)
        if not keys:
            continue
        section = node(data, dotted)
        enabled = section.get("enabled") if isinstance(section, dict) and "enabled" in section else node(
            defaults, dotted).get("enabled")
        if enabled:
            continue
        if dotted == "light" and ("illuminance_lux" in keys or "luminance_cd_m2" in keys):
            data.setdefault("light", {})["enabled"] = True
            key = "light.illuminance_lux" if "illuminance_lux" in keys else "light.luminance_cd_m2"
            out.append(f"{key} given: light in lux switched on (light.enabled=true)")
            continue
        shown = ", ".join(f"{dotted}.{k}" for k in keys)
        out.append(f"{shown} set while {dotted}.enabled is false: no effect (set {dotted}.enabled=true to use it)")
    sensor: dict = given["sensor"] if isinstance(given.get("sensor"), dict) else {}
    if "pixel_pitch_um" in sensor:
        dark = data.get("dark_current", {}) if isinstance(data.get("dark_current"), dict) else {}
        points = dark.get("points", defaults["dark_current"]["points"])
        if not any(isinstance(p, dict) and p.get("mean_nA_per_cm2") is not None for p in points or []):
            out.append(f"sensor.pixel_pitch_um = {sensor['pixel_pitch_um']}: the dark current is per pixel "
                       "(dark_current.points' e-/s or aA) and stays as it was; give their mean_nA_per_cm2 to "
                       "scale it with the pixel's area")
    return out


def config_values(config: Config) -> dict:
    """The values ``config`` set, as data (what :func:`apply_values` and :func:`merge_updates` change: a value set
    to None stays set, and what was never set keeps its default when validated again)."""
    return config.model_dump(mode="json", exclude_unset=True)


@functools.lru_cache(maxsize=1)
def default_data() -> dict:
    """The schema's defaults as data, made once (where ``--set`` and ``--vary`` find a list the data do not hold;
    read, never changed)."""
    return Config().model_dump(mode="json")


def merge_updates(config: Config, updates: dict) -> Config:
    """A new schema-valid configuration: ``config`` with ``updates`` merged in.

    Every value ``config`` set is kept, ``None`` included (a ``tail: null``
    stays no tail): the merge starts from the keys that were set, not from a
    dump that leaves nulls out, and what was never set keeps its default.

    Parameters
    ----------
    config : Config
        The configuration to change.
    updates : dict
        A (partial) configuration as data, sections as nested dicts, merged over ``config``.

    Returns
    -------
    Config
        Schema-valid (what the values imply is checked by :func:`cmosnoise.resolve`).

    Examples
    --------
    >>> from cmosnoise import load_config, merge_updates
    >>> base = load_config(overrides=["sensor.temperature_c=45"])
    >>> changed = merge_updates(base, {"prnu": {"sigma_pct": 2}})
    >>> changed.prnu.sigma_pct, changed.sensor.temperature_c
    (2.0, 45.0)
    """
    try:
        return _merged_by_section(config, updates)
    except (ValueError, TypeError, AttributeError):  # a ValidationError too: the whole validation below says what
        pass
    return validate_data(deep_merge(config_values(config), updates))


def _merged_by_section(config: Config, updates: dict) -> Config:
    """:func:`merge_updates`' result, made by validating only what ``updates`` names.

    Each section that ``updates`` names is validated again from its set
    values with the update merged in (what the whole validation does to it),
    every other top-level value is validated as it is assigned, and the
    configuration's own checks (``Config._check_across_sections``, which only raise)
    run on each assignment, or once where there is none; the sections it
    does not name are shared with ``config``, already valid. The same
    configuration as validating the whole merged data, values and set keys
    alike (``tests/test_config.py`` holds them equal over every preset and
    gain row), at a fraction of its cost: a data set's sample and a gain
    row each change a few of some 25 sections. Raises whatever the
    validation raises, for :func:`merge_updates` to say it as the whole
    validation does.
    """
    sections, others = {}, {}
    for key, value in updates.items():
        current = getattr(config, key) if key in Config.model_fields else None
        if isinstance(current, BaseModel) and isinstance(value, dict):
            section = current.model_dump(mode="json", exclude_unset=True)  # a fresh dict: merged into, not copied
            _merge_into(section, value)
            sections[key] = type(current).model_validate(section)
        else:
            others[key] = value
    # the validated sections put in at once (marked set), then every other value assigned, validated as it is
    # (each assignment runs the configuration's own checks); with none, those checks run once, on the whole
    out = config.model_copy(update=sections)
    for key, value in others.items():
        setattr(out, key, value)
    if not others:
        out._check_across_sections()
    return out
