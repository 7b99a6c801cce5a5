"""The one error type a user can cause; the CLI prints it without a traceback and exits 2."""

from __future__ import annotations


class DiviewerError(Exception):
    """A problem with the user's input: a bad scene file, a model for another scene, a missing extra.

    The message names the file, the field and, where there is one, the fix.
    """

    def __init__(self, message: str, *, path: object | None = None, field: str | None = None):
        where = ""
        if path is not None:
            where = f"{path}"
            if field:
                where += f": {field}"
            where += ": "
        elif field:
            where = f"{field}: "
        super().__init__(where + message)
        self.path = path
        self.field = field


def missing_extra(module: str, extra: str = "train") -> DiviewerError:
    """Error for an optional dependency that is not installed, naming the extra that provides it."""
    torch_hint = " (for a CPU-only torch first run: pip install torch==2.13.0)" if module == "torch" else ""
    return DiviewerError(
        f"this command needs the Python package '{module}', which is not installed; "
        f"install the '{extra}' extra: pip install 'diviewer[{extra}]'{torch_hint}"
    )
