"""Effects that a mill model is assembled from; one module per physical mechanism, a registry
of their names (``EFFECTS``) and the interface a new effect implements (``Effect``)."""

from .base import Effect
from .registry import EFFECTS, known_effects, resolve

__all__ = ["EFFECTS", "Effect", "known_effects", "resolve"]
