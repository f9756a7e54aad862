"""The scene-file reference, generated from the schema itself so that it cannot drift.

    python -m scenarios.scene.reference > docs/scenes.md

Every key of every section with its type, unit, default, allowed values, an example and its
description (the field's docstring in :mod:`scenarios.scene.schema`); the effects and their
options from the twin's registry; the shipped scenes. A test regenerates the page and compares.

Units: a field's ``json_schema_extra["unit"]`` where its name does not say it, else the name's
suffix (:data:`SUFFIX_UNITS`); a bound suffix ``_min``/``_max`` is dropped first.
"""

from __future__ import annotations

import sys
import tomllib
import types
from importlib import resources
from typing import Any, Literal, Union, get_args, get_origin

import annotated_types as at
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from scenarios.scene.keypaths import unwrap
from scenarios.scene.schema import Scene, Section

COMMAND = "python -m scenarios.scene.reference > docs/scenes.md"

#: Name suffix -> unit, longest first (the house convention: names carry units).
SUFFIX_UNITS = (("_frac_critical", "fraction of critical speed"), ("_tph_per_h", "t/h per h"),
                ("_kwh_t", "kWh/t"), ("_per_h", "1/h"), ("_tph", "t/h"), ("_um", "µm"), ("_kg", "kg"),
                ("_kw", "kW"), ("_h", "h"), ("_m", "m"), ("_frac", "fraction"), ("_pct", "%"))

#: Sections of the file, in the order of the page: (TOML header, key path into Scene).
SECTIONS = (("top level", ()), ("[scene]", ("scene",)), ("[mill]", ("mill",)),
            ("[mill.size_classes]", ("mill", "size_classes")), ("[ores.NAME]", ("ores", "*")),
            ("[ores.NAME.texture]", ("ores", "*", "texture")), ("[ores.NAME.breakage]", ("ores", "*", "breakage")),
            ("[feed]", ("feed",)), ("[feed.psd]", ("feed", "psd")),
            ("[[feed.schedule]]", ("feed", "schedule", 0)), ("[controller]", ("controller",)),
            ("[controller.weights]", ("controller", "weights")),
            ("[controller.bounds]", ("controller", "bounds")), ("[sensors]", ("sensors",)),
            ("[plant]", ("plant",)))


def unit_of(name: str, field) -> str:
    extra = field.json_schema_extra if isinstance(field.json_schema_extra, dict) else {}
    if "unit" in extra:
        return str(extra["unit"])
    base = name.removesuffix("_min").removesuffix("_max")
    for suffix, unit in SUFFIX_UNITS:
        if base.endswith(suffix):
            return unit
    return "-"


def type_text(ann: Any) -> str:
    """A TOML reader's name for an annotation."""
    origin = get_origin(ann)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(ann) if a is not type(None)]
        text = " or ".join(type_text(a) for a in args)
        return text + " (optional)" if len(args) < len(get_args(ann)) else text
    if origin is Literal:
        return "string" if all(isinstance(a, str) for a in get_args(ann)) else "value"
    if origin is list:
        return f"list of {type_text(get_args(ann)[0])}"
    if origin is dict:
        return f"table of {type_text(get_args(ann)[1])}"
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return "table"
    return {str: "string", float: "float", int: "integer", bool: "boolean"}.get(ann, "any")


def _num(v) -> str:
    """A bound: integral floats without exponent or decimals (1000000, not 1e+06)."""
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def toml_value(v: Any) -> str:
    """A value as it is written in a scene file."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, float):
        return repr(v) if len(repr(v)) <= 8 else f"{v:.6g}"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return str(v)


def default_text(field) -> str:
    if field.default_factory is not None:
        value = field.default_factory()
        return "its table's defaults" if isinstance(value, BaseModel) else toml_value(value) if value else "empty"
    if field.default is PydanticUndefined:
        return "required"
    return "not set" if field.default is None else toml_value(field.default)


_BOUNDS = ((at.Gt, "> {}", "gt"), (at.Ge, ">= {}", "ge"), (at.Lt, "< {}", "lt"), (at.Le, "<= {}", "le"))


def allowed_text(path: tuple, name: str, field) -> str:
    """Allowed values: Literal words, bounds, lengths, and the sets the twin defines."""
    dynamic = _dynamic_allowed().get(path + (name,))
    if dynamic:
        return dynamic
    base = unwrap(field.annotation)
    if get_origin(base) is Literal:
        return ", ".join(toml_value(a) for a in get_args(base))
    parts = [fmt.format(_num(getattr(meta, attr))) for meta in field.metadata
             for cls, fmt, attr in _BOUNDS if isinstance(meta, cls)]
    lengths = {type(m): m for m in field.metadata if isinstance(m, (at.MinLen, at.MaxLen))}
    lo, hi = lengths.get(at.MinLen), lengths.get(at.MaxLen)
    if lo and hi and lo.min_length == hi.max_length:
        parts.append(f"exactly {lo.min_length} entries")
    elif lo:
        parts.append(f"at least {lo.min_length} entries" if get_origin(base) is list else "not empty")
    return ", ".join(parts) or "any"


def _dynamic_allowed() -> dict[tuple, str]:
    """Allowed values that live in the twin (effect names, minerals) or in the file (ores)."""
    from twin import known_effects
    from twin.ore import mineral_names

    effects = ", ".join(f"`{e}`" for e in known_effects())
    ores = "ores of `[ores]`, fractions in [0, 1] summing to 1"
    return {("effects",): effects, ("plant", "effects"): effects,
            ("effect_options",): "listed effects and their options (see Effects)",
            ("plant", "effect_options"): "the plant's effects and their options (see Effects)",
            ("ores", "*", "mineralogy"): "minerals: " + ", ".join(mineral_names()) + "; wt% >= 0",
            ("feed", "blend"): ores, ("feed", "schedule", 0, "blend"): ores,
            ("mill", "preset"): "`\"lab\"`, `\"industrial\"`, or a path ending in .json"}


#: The scene whose values are the examples first (the most complete), and that is shown in full.
EXAMPLE_SCENE = "reference_transition.toml"


def _shipped_scenes() -> dict[str, dict]:
    """The shipped scenes by file name, :data:`EXAMPLE_SCENE` first, then by name."""
    root = resources.files("scenarios")
    files = sorted((p for p in root.iterdir() if p.name.endswith(".toml")),
                   key=lambda p: (p.name != EXAMPLE_SCENE, p.name))
    return {p.name: tomllib.loads(p.read_text(encoding="utf-8")) for p in files}


def example_text(path: tuple, name: str, field, scenes: dict[str, dict]) -> str:
    """The field's ``examples``, else its value in the first shipped scene that sets it, else
    its default ("" if it has none of these)."""
    if field.examples:
        return toml_value(field.examples[0])
    for data in scenes.values():
        for value in _lookup(data, path + (name,)):
            return toml_value(value)
    if field.default not in (None, PydanticUndefined):
        return toml_value(field.default)
    return ""


def all_sections() -> list[tuple[str, tuple, type[Section]]]:
    """Every section of the page: (header, key path, model)."""
    return [(header, path, section_model(path)) for header, path in SECTIONS]


def missing_documentation(models=None) -> list[str]:
    """``Model.field: what is missing`` for every field without a description or an example."""
    scenes = _shipped_scenes()
    out = []
    for path, model in models or [(p, m) for _, p, m in all_sections()]:
        for name, field in model.model_fields.items():
            if not (field.description or "").strip():
                out.append(f"{model.__name__}.{name}: no description")
            sub = unwrap(field.annotation)
            is_table = isinstance(sub, type) and issubclass(sub, Section)
            if not is_table and not example_text(path, name, field, scenes):
                out.append(f"{model.__name__}.{name}: no example")
    return out


def _lookup(data: Any, path: tuple):
    """Values at a path with ``"*"`` for any key of a table and 0 for the first of a list."""
    if not path:
        yield data
        return
    step, rest = path[0], path[1:]
    if step == "*" and isinstance(data, dict):
        for value in data.values():
            yield from _lookup(value, rest)
    elif isinstance(step, int) and isinstance(data, list) and data:
        yield from _lookup(data[step], rest)
    elif isinstance(data, dict) and step in data:
        yield from _lookup(data[step], rest)


def section_model(path: tuple) -> type[Section]:
    model: Any = Scene
    for step in path:
        ann = unwrap(model.model_fields[step].annotation) if isinstance(step, str) and step != "*" else model
        if step == "*" or isinstance(step, int):
            continue
        while get_origin(ann) in (list, dict):
            ann = unwrap(get_args(ann)[-1])
        model = ann
    return model


def _cell(text: str) -> str:
    """One Markdown table cell: one line, reST literals as Markdown code."""
    return " ".join(text.split()).replace("``", "`").replace("|", "\\|")


TOP_LEVEL_TEXT = ("Keys before the first `[table]` of the file; every other top-level key is a section "
                  "below (`scene`, `mill`, `ores`, `feed`, `controller`, `sensors`, `plant`).")


def section_table(header: str, path: tuple, scenes: dict) -> list[str]:
    model = section_model(path)
    doc = _cell(model.__doc__ or "") if path else TOP_LEVEL_TEXT
    lines = [f"### `{header}`" if path else "### Top-level keys", "", doc, "",
             "| key | type | unit | default | allowed | example | meaning |", "|---|---|---|---|---|---|---|"]
    for name, field in model.model_fields.items():
        sub = unwrap(field.annotation)
        while get_origin(sub) in (list, dict):
            sub = unwrap(get_args(sub)[-1])
        if path == () and isinstance(sub, type) and issubclass(sub, Section):
            continue  # a section of its own below
        lines.append("| " + " | ".join(_cell(c) for c in (
            f"`{name}`", type_text(field.annotation), unit_of(name, field), default_text(field),
            allowed_text(path, name, field), f"`{example_text(path, name, field, scenes)}`"
            if example_text(path, name, field, scenes) else "", field.description or "")) + " |")
    return lines + [""]


def _option_default(value) -> str:
    """An option's default as TOML: a dataclass (the hydrocyclone) as the table of its fields."""
    if hasattr(value, "__dataclass_fields__"):
        return toml_value({k: getattr(value, k) for k in value.__dataclass_fields__})
    return toml_value(value)


def effects_section() -> list[str]:
    from twin import EFFECTS

    lines = ["## Effects", "", "A scene lists the effects its model contains; nothing else is computed. "
             "An effect may require others (the scene is refused, naming the missing one). Options go in "
             "`[effect_options.EFFECT]` (and `[plant.effect_options.EFFECT]` for the plant).", ""]
    for name, cls in EFFECTS.items():
        req = ", ".join(f"`{r}`" for r in cls.requires) or "nothing"
        lines += [f"### `{name}`", "", f"{cls.summary}. Requires {req}. Source: {cls.source}.", ""]
        if cls.outputs:
            lines += ["Adds to the model's outputs (the scalar ones are columns of a run): "
                      + ", ".join(f"`{o}`" for o in cls.outputs) + ".", ""]
        if cls.options:
            lines += ["| option | default | allowed | meaning |", "|---|---|---|---|"]
            lines += [f"| `{k}` | `{_cell(_option_default(opt.default))}` | {_cell(opt.allowed())} "
                      f"| {_cell(opt.description)} |" for k, opt in cls.options.items()]
            lines.append("")
    return lines


def render() -> str:
    """The reference page (Markdown)."""
    scenes = _shipped_scenes()
    lines = ["# Scene files: reference", "",
             f"<!-- Generated by `{COMMAND}` from scenarios/scene/schema.py; do not edit by hand. -->", "",
             "A scene is a TOML file: the mill, the ores and their schedule (or a recorded history), the "
             "physical effects to simulate, the controller and its tuning, the sensors. `grindtwin check "
             "SCENE.toml` validates a file as a whole and lists every problem with its key path "
             "(`FILE: feed.schedule[0].blend.D: ...`); `grindtwin run SCENE.toml` runs it. Names carry "
             "their units (`feed_tph`, `p80_um`, `speed_frac_critical` as 0.70, not 70). Unknown keys are "
             "errors; values are not converted (an integer is accepted where a float is expected).", "",
             "After validation, defaults that depend on other keys are filled in visibly: the mill's "
             "dimensions and `n_mixers` from its preset, the analyser's sample period from the scene's, "
             "and blends rescaled to sum exactly to 1.", "", "## Keys", ""]
    for header, path in SECTIONS:
        lines += section_table(header, path, scenes)
    lines += ["`[feed.history_texture]` and `[plant.size_classes]` have the keys of `[ores.NAME.texture]` and "
              "`[mill.size_classes]`.", ""]
    lines += effects_section()
    lines += ["## Shipped scenes", "", "| file | what it shows |", "|---|---|"]
    lines += [f"| `scenarios/{name}` | {_cell(data.get('scene', {}).get('description', ''))} |"
              for name, data in scenes.items()]
    ref = resources.files("scenarios").joinpath(EXAMPLE_SCENE).read_text(encoding="utf-8")
    lines += ["", f"### Example: `scenarios/{EXAMPLE_SCENE}`", "", "```toml", ref.rstrip(), "```", ""]
    return "\n".join(lines)


def main() -> int:
    sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
