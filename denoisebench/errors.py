"""Exceptions shared by every stage. The CLI maps them to exit codes (DESIGN.md, Command line)."""


class DenoisebenchError(Exception):
    """Base class. Messages are one line, written for the user."""


class UserInputError(DenoisebenchError):
    """Bad user input (a file that does not parse, a stage without camera, a bad option): exit 2."""
