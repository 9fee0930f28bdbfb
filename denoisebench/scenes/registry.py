"""The scene families by name: ``FAMILIES``, :func:`list_families`, :func:`get_family`."""

from __future__ import annotations

from denoisebench.errors import UserInputError
from denoisebench.scenes.families import ALL
from denoisebench.scenes.family import SceneFamily

__all__ = ["FAMILIES", "SceneFamily", "UnknownFamilyError", "get_family", "list_families"]


class UnknownFamilyError(UserInputError, ValueError):
    """A family name that is not registered (the CLI maps it to exit 2)."""


FAMILIES: dict[str, SceneFamily] = {fam.name: fam for fam in ALL}


def list_families() -> list[SceneFamily]:
    """Every registered family, in registration order."""
    return list(FAMILIES.values())


def get_family(name: str) -> SceneFamily:
    """The family called ``name``; :class:`UnknownFamilyError` (a ValueError) lists the known ones."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise UnknownFamilyError(f"unknown scene family {name!r}; known: {', '.join(FAMILIES)}") from None
