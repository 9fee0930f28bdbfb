"""Exceptions shared by every stage. The CLI maps them to exit codes (docs/architecture.md, Command line)."""


class DenoisebenchError(Exception):
    """Base class. Messages are one line, written for the user."""


class UserInputError(DenoisebenchError):
    """Bad user input (a file that does not parse, a stage without camera, a bad option): exit 2."""


def one_line(error: BaseException) -> str:
    """``"TypeName: first line of the message"`` (or the type's name alone for an empty message): how a
    failure is reported in tables, manifests and stderr, where a multi-line traceback text would not fit."""
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[0]}" if lines and lines[0].strip() else type(error).__name__
