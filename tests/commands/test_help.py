"""The command line's --help texts name what the registries hold."""

from __future__ import annotations

import re

from denoisebench import cli
from denoisebench.models.names import MODEL_NAMES


def test_top_level_help_names_every_trainable_model():
    listed = re.search(r"\(([^)]*)\)", cli.COMMANDS["train"][1]).group(1)
    assert [name.strip() for name in listed.split(",")] == list(MODEL_NAMES)
