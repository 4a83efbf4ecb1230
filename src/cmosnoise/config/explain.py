"""``cmosnoise config --explain``: every key with its type, default, limits and description, from the schema."""

from __future__ import annotations

import types
import typing
from typing import Any

from pydantic import BaseModel

from .schema import Config

_DEFAULT_TEXT = {"enabled": "switch this stage (or part) on or off"}


def _is_union(ann) -> bool:
    """Whether ``ann`` is a union, ``Optional[X]`` or ``X | None`` alike (two origins since Python 3.10)."""
    return typing.get_origin(ann) in (typing.Union, types.UnionType)


def _limits(info) -> str:
    parts = []
    for m in info.metadata:
        for attr, sym in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
            v = getattr(m, attr, None)
            if v is not None:
                parts.append(f"{sym} {v:g}" if isinstance(v, (int, float)) else f"{sym} {v}")
    return ", ".join(parts)


def _type_name(ann) -> str:
    origin = typing.get_origin(ann)
    args = typing.get_args(ann)
    if origin is typing.Literal:
        return " | ".join(map(str, args))
    if _is_union(ann):
        names = [_type_name(a) for a in args if a is not type(None)]
        return " | ".join(names) + (" | null" if type(None) in args else "")
    if origin in (list, tuple):
        return f"list of {_type_name(args[0])}" if args else "list"
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return "section"
    return getattr(ann, "__name__", str(ann))


def _submodel(ann) -> type[BaseModel] | None:
    """The section class a field holds (directly, optionally, or as list items), if any."""
    for a in (ann, *typing.get_args(ann)):
        if isinstance(a, type) and issubclass(a, BaseModel):
            return a
        for b in typing.get_args(a):
            if isinstance(b, type) and issubclass(b, BaseModel):
                return b
    return None


def rows(model: type[BaseModel] = Config, prefix: str = "") -> list[dict[str, Any]]:
    """One row per key: ``key``, ``type``, ``default``, ``limits``, ``description`` (lists of sections as ``key.N.sub``)."""
    out = []
    for name, info in model.model_fields.items():
        key = f"{prefix}{name}"
        sub = _submodel(info.annotation)
        is_list = typing.get_origin(info.annotation) is list or any(
            typing.get_origin(a) is list for a in typing.get_args(info.annotation))
        if sub is not None and not is_list and not _is_union(info.annotation):
            out.extend(rows(sub, key + "."))
            continue
        default = "required" if info.is_required() else info.get_default(call_default_factory=True)
        if isinstance(default, BaseModel):
            default = default.model_dump(mode="json", exclude_none=True)
        elif isinstance(default, list) and default and isinstance(default[0], BaseModel):
            default = f"{len(default)} item(s); see `cmosnoise config`"
        out.append({"key": key, "type": _type_name(info.annotation), "default": default,
                    "limits": _limits(info), "description": info.description or _DEFAULT_TEXT.get(name, "")})
        if sub is not None:  # a list of sections, or an optional one: its keys too
            out.extend(rows(sub, key + (".N." if is_list else ".")))
    return out


def text(model: type[BaseModel] = Config) -> str:
    """The rows as plain text, one block per key."""
    lines = []
    for r in rows(model):
        default = "null" if r["default"] is None else ('""' if r["default"] == "" else r["default"])
        head = f"{r['key']}  ({r['type']}; default {default}"
        head += f"; {r['limits']})" if r["limits"] else ")"
        lines.append(head)
        if r["description"]:
            lines.append(f"    {r['description']}")
    return "\n".join(lines) + "\n"


def fields(model: type[BaseModel] = Config, prefix: str = "") -> list[dict[str, Any]]:
    """The rows of :func:`rows` with what a form needs: ``kind`` (number, integer, bool, enum, text, json),
    ``choices`` (enum), ``min`` and ``max`` (numbers, from the schema's limits; None where open)."""
    out = []
    for r in rows(model, prefix):
        info = _field_info(model, r["key"])
        kind, choices, lo, hi = "json", None, None, None
        if info is not None:
            ann = info.annotation
            args = [a for a in typing.get_args(ann) if a is not type(None)] if _is_union(ann) else [ann]
            base = args[0] if len(args) == 1 else ann
            if typing.get_origin(base) is typing.Literal:
                kind, choices = "enum", list(typing.get_args(base))
            elif base is bool:
                kind = "bool"
            elif base is int:
                kind = "integer"
            elif base is float:
                kind = "number"
            elif base is str:
                kind = "text"
            for m in info.metadata:  # a bound is inclusive (ge, le) or not (gt, lt): either way, the slider's end
                for attr in ("ge", "gt"):
                    lo = getattr(m, attr, None) if getattr(m, attr, None) is not None else lo
                for attr in ("le", "lt"):
                    hi = getattr(m, attr, None) if getattr(m, attr, None) is not None else hi
        out.append({**r, "kind": kind, "choices": choices, "min": lo, "max": hi,
                    "nullable": info is not None and not info.is_required() and info.get_default() is None})
    return out


def _field_info(model: type[BaseModel], key: str):
    """The pydantic FieldInfo of a dotted key (list items as N)."""
    node = model
    parts = key.split(".")
    for i, part in enumerate(parts):
        if part == "N":
            continue
        info = node.model_fields.get(part)
        if info is None:
            return None
        if i == len(parts) - 1:
            return info
        sub = _submodel(info.annotation)
        if sub is None:
            return None
        node = sub
    return None
