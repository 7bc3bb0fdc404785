"""Errors the CLI turns into one line on stderr and exit code 2."""


class UserError(Exception):
    """Bad input from the user: a file, a parameter or a command-line argument.

    The message is complete on its own (it names what is wrong and where); the CLI prints it
    as one line without a traceback.
    """


class SimulationError(UserError):
    """A component failed during a run; results computed so far have been written."""


def where(path, line=None) -> str:
    """'file' or 'file:line' for messages."""
    return f"{path}:{line}" if line else f"{path}"
