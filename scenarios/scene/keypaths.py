"""Key paths into scenes: ``feed.schedule[1].blend.D`` <-> ``("feed", "schedule", 1, "blend", "D")``.

Also walks the schema's types along a path, which gives the allowed keys at any point (for
"did you mean" messages) and lets a sweep check a path before it sets it.
"""

from __future__ import annotations

import difflib
import re
import types
from typing import Annotated, Any, Union, get_args, get_origin

from pydantic import BaseModel

_STEP = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def format_path(loc: tuple) -> str:
    """``("feed", "schedule", 1, "blend")`` -> ``"feed.schedule[1].blend"``."""
    out = ""
    for step in loc:
        if isinstance(step, int):
            out += f"[{step}]"
        else:
            out += ("." if out else "") + str(step)
    return out or "(top level)"


def parse_path(path: str) -> tuple:
    """``"feed.schedule[1].blend.D"`` -> ``("feed", "schedule", 1, "blend", "D")``."""
    steps: list[str | int] = []
    pos = 0
    for m in _STEP.finditer(path):
        gap = path[pos:m.start()]
        if gap not in ("", "."):
            raise ValueError(f"cannot read key path {path!r} near {gap!r}")
        steps.append(m.group(1) if m.group(1) is not None else int(m.group(2)))
        pos = m.end()
    if not steps or path[pos:] != "":
        raise ValueError(f"cannot read key path {path!r}")
    return tuple(steps)


def did_you_mean(name: str, known) -> str:
    """``" (did you mean 'x'?)"`` for close matches of ``name`` in ``known``, else ``""``."""
    hits = difflib.get_close_matches(str(name), [str(k) for k in known], n=3, cutoff=0.6)
    if not hits:
        return ""
    return " (did you mean " + " or ".join(repr(h) for h in hits) + "?)"


def unwrap(annotation: Any) -> Any:
    """Strip ``Optional``/``Annotated`` so that the underlying type remains."""
    origin = get_origin(annotation)
    if origin is Annotated:
        return unwrap(get_args(annotation)[0])
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        return unwrap(args[0]) if len(args) == 1 else annotation
    return annotation


def is_model(annotation: Any) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, BaseModel)


def type_at(model: type[BaseModel], loc: tuple) -> Any:
    """The schema type at ``loc`` below ``model``; raises ``KeyError(step, allowed)`` if none."""
    ann: Any = model
    for step in loc:
        ann = unwrap(ann)
        origin = get_origin(ann)
        if ann is Any:  # free-form below here (an effect's options table): its owner checks the keys
            return Any
        if is_model(ann):
            if step not in ann.model_fields:
                raise KeyError(step, sorted(ann.model_fields))
            ann = ann.model_fields[step].annotation
        elif origin is dict:
            if not isinstance(step, str):
                raise KeyError(step, ["a name"])
            ann = get_args(ann)[1]
        elif origin in (list, tuple):
            if not isinstance(step, int):
                raise KeyError(step, ["an index [n]"])
            args = get_args(ann)
            ann = args[0] if origin is list or len(args) == 0 else args[min(step, len(args) - 1)]
        else:
            raise KeyError(step, [])
    return unwrap(ann)


def allowed_keys(model: type[BaseModel], loc: tuple) -> list[str]:
    """Field names of the section at ``loc`` (empty if it is not a section)."""
    try:
        ann = type_at(model, loc)
    except KeyError:
        return []
    return sorted(ann.model_fields) if is_model(ann) else []
