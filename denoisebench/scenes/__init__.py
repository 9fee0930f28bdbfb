"""Procedural scene families that author USD stages, and the effects vocabulary.

``denoisebench.scenes.effects`` is importable on its own (no USD); the family registry is loaded
on first use of ``FAMILIES``, ``list_families``, ``get_family`` or ``SceneFamily``::

    from denoisebench.scenes import get_family
    path = get_family("cornell").author("out/cornell_3", seed=3, frames=8)

This package never imports Mitsuba: USD is the interchange format.
"""

from __future__ import annotations

from denoisebench.scenes.effects import EFFECTS, METADATA_KEY, validate_effects

# Lazy imports: the family registry (it authors USD: pxr) only when a family is asked for.

_REGISTRY_NAMES = ("FAMILIES", "list_families", "get_family", "SceneFamily", "UnknownFamilyError")

__all__ = ["EFFECTS", "METADATA_KEY", "validate_effects", *_REGISTRY_NAMES]


def __getattr__(name: str):
    if name in _REGISTRY_NAMES:
        from denoisebench.scenes import registry

        return getattr(registry, name)
    raise AttributeError(f"module 'denoisebench.scenes' has no attribute {name!r}")
