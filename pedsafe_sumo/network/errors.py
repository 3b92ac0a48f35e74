"""The error of a site build: one line saying which step failed and why."""


class BuildError(RuntimeError):
    """A step of the build failed; the message says which and why."""
