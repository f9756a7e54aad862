"""Load and validate scene files as a whole, reporting every error at once.

Two passes over the file: the pydantic schema (:mod:`scenarios.scene.schema`) checks each field,
then :mod:`scenarios.scene.checks` checks what relates fields to each other. Both passes always
run, so a file with five mistakes gets five messages. Each message reads
``FILE: key.path: what is wrong and what is allowed (got VALUE)``.

After validation, defaults that depend on other fields are filled in visibly (the returned
``Scene`` shows them): mill dimensions and ``n_mixers`` from the preset, the P80 analyser's
sample period (the scene's), and blends are rescaled to sum to 1 (they must already sum to 1
within the twin's ``blend_sum_tolerance``; ``twin.ore.normalised_blend``, as the twin rescales them).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from pydantic import ValidationError

from scenarios.scene.checks import cross_check
from scenarios.errors import SceneError
from scenarios.scene.keypaths import allowed_keys, did_you_mean, format_path, type_at
from scenarios.scene.schema import Scene, mill_preset
from twin import file_sha256
from twin.ore import normalised_blend


#: Byte-order marks of text encodings that are not UTF-8, to name the encoding in the error.
TEXT_BOMS = ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"), (b"\xff\xfe", "UTF-16"),
             (b"\xfe\xff", "UTF-16"))


def read_toml(path: str | Path, what: str = "scene file") -> dict[str, Any]:
    """The raw TOML table of a scene file (or another ``what``); SceneError if missing or not TOML."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    # ASCII in UTF-16 without a byte-order mark decodes as UTF-8 (its zero bytes are characters): TOML then
    # failed at line 1 column 2
    found = next((f"{name} text" for bom, name in TEXT_BOMS if raw.startswith(bom)), None) or _without_bom(raw[:64])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        found = found or f"byte {exc.start} is 0x{raw[exc.start]:02x}"
    if found:
        raise SceneError(f"{path}: not UTF-8 text ({'it is ' * found.endswith('text')}{found}); a TOML {what} must "
                         "be UTF-8: save it again as UTF-8") from None
    try:
        return tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None


def _without_bom(head: bytes) -> str | None:
    """What a file that is not UTF-8 and has no byte-order mark looks like from its first bytes: wide text
    (ASCII in UTF-16 or UTF-32 has a zero byte in every other, or three of four, places), a binary file (a
    zero byte elsewhere: an executable was called UTF-16 text), or None."""
    if b"\x00" not in head:
        return None
    wide = len(head) >= 4 and any(all(b == 0 for b in head[k::2]) for k in (0, 1))
    return "UTF-16 or UTF-32 text" if wide else "a binary file, not text"


def validate_scene_dict(data: dict[str, Any], source_path: str | Path | None = None, as_written: bool = False,
                        ) -> tuple[Scene | None, list[str]]:
    """Validate a raw scene table; return ``(scene, [])`` or ``(None, messages)``. ``as_written``: the table is
    the file's own, not one a program derived from it (:func:`scenarios.scene.checks.cross_check`)."""
    source = Path(source_path) if source_path is not None else None
    label = str(source) if source is not None else "<scene>"
    errors: list[str] = []
    scene: Scene | None = None
    try:
        scene = Scene.model_validate(data)
    except ValidationError as exc:
        errors += [pydantic_message(label, e) for e in exc.errors()]
    base_dir = source.parent if source is not None else Path.cwd()
    errors += [f"{label}: {m}" for m in cross_check(data, base_dir, as_written)]
    errors = list(dict.fromkeys(errors))  # keep order, drop repeats
    if errors:
        return None, errors
    assert scene is not None
    scene._source_path = source
    preset = scene.mill_spec()
    if isinstance(preset, Path):  # hashed as loaded, before any work (a run warns when it changed by its end)
        scene._preset_file_sha256 = file_sha256(preset)
    _fill_defaults(scene)
    return scene, []


def scene_from_dict(data: dict[str, Any], source_path: str | Path | None = None, as_written: bool = False,
                    ) -> Scene:
    """Validated ``Scene`` from a raw table; SceneError listing every problem otherwise."""
    scene, errors = validate_scene_dict(data, source_path, as_written)
    if errors:
        raise SceneError(_summary(source_path, errors))
    return scene


def load_scene(path: str | Path) -> Scene:
    """Read, validate and complete a scene file; SceneError listing every problem."""
    return scene_from_dict(read_toml(path), path, as_written=True)


def check_scene(path: str | Path) -> list[str]:
    """Every problem in a scene file, one message each; empty list when it is valid."""
    try:
        data = read_toml(path)
    except SceneError as exc:
        return [str(exc)]
    return validate_scene_dict(data, path, as_written=True)[1]


def _summary(source_path, errors: list[str]) -> str:
    where = source_path if source_path is not None else "scene"
    head = f"{where}: {len(errors)} problem{'s' if len(errors) > 1 else ''} in the scene"
    return head + "\n  " + "\n  ".join(errors)


def pydantic_message(label: str, err: dict, model: type = Scene) -> str:
    """One pydantic error of a file validated against ``model`` as ``LABEL: key.path: what is
    wrong and what is allowed (got VALUE)``."""
    loc = tuple(err["loc"])
    path = format_path(loc)
    kind = err["type"]
    if kind == "missing":
        return f"{label}: {path}: required key is missing"
    if kind == "extra_forbidden":
        key = loc[-1]
        allowed = allowed_keys(model, loc[:-1])
        hint = ""
        if len(loc) > 1 and key in model.model_fields:
            hint = (f" ({key!r} is a top-level key: in TOML it must come before the first "
                    "[table], else it belongs to that table)")
        return (f"{label}: {path}: unknown key {key!r}{did_you_mean(key, allowed)}; "
                f"allowed keys: {', '.join(allowed)}{hint}")
    hint = ""
    if kind == "literal_error":
        try:
            ann = type_at(model, loc)
        except KeyError:
            ann = None
        if get_origin(ann) is Literal:
            hint = did_you_mean(err["input"], get_args(ann))
    msg = err["msg"].removeprefix("Value error, ")  # pydantic's prefix to a validator's own message
    return f"{label}: {path}: {msg}{hint} (got {err['input']!r})"


def _fill_defaults(scene: Scene) -> None:
    mill = scene.mill
    if mill.n_mixers is None and mill.mixer_volume_fracs is not None:
        mill.n_mixers = len(mill.mixer_volume_fracs)
    for key, value in mill_preset(scene.mill_spec()).items():
        if getattr(mill, key) is None:
            setattr(mill, key, value)
    if scene.sensors.p80_sample_period_h is None:
        scene.sensors.p80_sample_period_h = scene.scene.sample_period_h
    blends = [ev.blend for ev in scene.feed.schedule]
    if scene.feed.blend is not None:
        blends.append(scene.feed.blend)
    for blend in blends:
        blend.update(zip(list(blend), normalised_blend(blend.values())))
