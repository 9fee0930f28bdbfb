"""The dataset's error type: a bad or incomplete dataset on disk is the user's input (exit 2)."""

from __future__ import annotations

from denoisebench.errors import UserInputError


class DatasetError(UserInputError):
    """A dataset file is missing, corrupt, holds NaN/Inf, or does not match its manifest.

    Messages are one line and name the file (and scene/frame where known).
    """
