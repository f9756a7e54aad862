"""Effects that a mill model is assembled from; one module per physical mechanism, a registry
of their names (``EFFECTS``) and the interface a new effect implements (``Effect``)."""

from .base import Effect, EffectContext, Option
from .registry import EFFECTS, Problem, build_order, known_effects, problems, resolve

__all__ = ["EFFECTS", "Effect", "EffectContext", "Option", "Problem", "build_order", "known_effects", "problems", "resolve"]
