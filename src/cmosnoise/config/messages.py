"""Validation errors as one line a user can act on: ``key = value: what is allowed``."""

from __future__ import annotations

from pydantic import ValidationError


def _format_loc(loc) -> str:
    parts = []
    for p in loc:
        if isinstance(p, int):
            parts.append(f"[{p}]")
        elif str(p).startswith(("list[", "dict[", "function-")):
            continue  # pydantic's union-branch labels, not user keys
        else:
            parts.append(("." if parts else "") + str(p))
    return "".join(parts)


def format_validation_error(err: ValidationError) -> str:
    """One line per problem: ``key = value: what is allowed``."""
    lines = []
    seen = set()
    errors = err.errors()
    for e in errors[:MAX_PROBLEMS]:
        key = _format_loc(e.get("loc", ()))
        msg = e.get("msg", "invalid")
        msg = msg.removeprefix("Value error, ")
        if e.get("type") == "extra_forbidden":
            parent = key.rsplit(".", 1)[0] if "." in key else ""
            line = f"unknown key '{key}'" + (f" in section '{parent}'" if parent else "")
            near = _near_keys(e.get("loc", ()))
            if near:
                line += f" (did you mean {' or '.join(repr(k) for k in near)}?)"
        elif "input" in e and not isinstance(e["input"], dict) and key:
            line = f"{key} = {_short(repr(e['input']))}: {msg}"
        else:
            line = f"{key}: {msg}" if key else msg
        if line not in seen:
            seen.add(line)
            lines.append(line)
    if len(errors) > MAX_PROBLEMS:
        lines.append(f"and {len(errors) - MAX_PROBLEMS} more")
    return "invalid configuration: " + "; ".join(lines)


#: an error message lists at most this many problems, each value cut to MAX_VALUE characters
MAX_PROBLEMS = 5
MAX_VALUE = 60


def _near_keys(loc) -> list[str]:
    """The keys of the section that ``loc`` names closest to its last part (a typo's likely meaning)."""
    import difflib

    from pydantic import BaseModel

    from .schema import Config

    model: type[BaseModel] = Config
    names = [p for p in loc if isinstance(p, str) and not p.startswith(("list[", "dict[", "function-"))]
    for part in names[:-1]:
        field = model.model_fields.get(part)
        if field is None:
            return []
        sub = field.annotation
        for arg in (getattr(sub, "__args__", None) or (sub,)):  # Optional[Section], list[Section]
            inner = getattr(arg, "__args__", None)
            arg = inner[0] if inner else arg
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                model = arg
                break
        else:
            return []
    if not names:
        return []
    return difflib.get_close_matches(names[-1], list(model.model_fields), n=2, cutoff=0.6)


def _short(text: str) -> str:
    return text if len(text) <= MAX_VALUE else text[: MAX_VALUE - 3] + "..."


