"""Scenes: the TOML schema (one pydantic model per section), loading and whole-file validation
with key paths, the cross-field checks, recorded histories, and the feed over time."""

from scenarios.scene.history import RECORDED_COLUMNS, TEXTURE_COLUMNS, History, read_history, read_history_once
from scenarios.scene.keypaths import did_you_mean, format_path, parse_path, type_at
from scenarios.scene.loader import (check_scene, load_scene, pydantic_message, read_toml, scene_from_dict,
                                    validate_scene_dict)
from scenarios.scene.schedule import blend_at, event_started, feed_table, load_history, ore_column, ore_mineralogies
from scenarios.scene.schema import CONTROLLER_KINDS, ORE_TYPES, Scene, mill_preset

__all__ = ["CONTROLLER_KINDS", "History", "ORE_TYPES", "RECORDED_COLUMNS", "Scene", "TEXTURE_COLUMNS", "blend_at",
           "check_scene", "did_you_mean", "event_started", "feed_table", "format_path", "load_history", "load_scene",
           "mill_preset", "ore_column", "ore_mineralogies", "parse_path", "pydantic_message", "read_history",
           "read_history_once", "read_toml", "scene_from_dict", "type_at", "validate_scene_dict"]
