"""Errors that name a parameter: the library speaks in its own parameter names, the command line in its flags.

A message marks each parameter it names in backticks: ``ParameterError("`spp` must be at least 1, got 0")``. Read
from Python, ``str(exc)`` names the parameter as the caller passed it (``spp must be at least 1, got 0``); the
command line renders the same error with ``render(flag_of)`` (``--spp must be at least 1, got 0``), translating
every name in one place (``inkopt.cli.common.flag_of``). Only backticked Python identifiers are parameter names;
values (paths, numbers) are never rewritten.
"""

from __future__ import annotations

import re
from collections.abc import Callable

__all__ = ["ParameterError"]

_NAME = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


class ParameterError(ValueError):
    """A bad value of a named parameter (a ``ValueError``). ``template`` is the message with every parameter name
    in backticks; ``parameters`` lists those names in order of appearance."""

    def __init__(self, template: str):
        self.template = template
        self.parameters = tuple(dict.fromkeys(_NAME.findall(template)))
        super().__init__(self.render(lambda name: name))

    def render(self, name_of: Callable[[str], str]) -> str:
        """The message with each backticked parameter name replaced by ``name_of(name)``."""
        return _NAME.sub(lambda m: name_of(m.group(1)), self.template)
