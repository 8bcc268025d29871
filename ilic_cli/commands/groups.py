"""Option groups: several click options that reach a command as one typed settings object.

``@option_group("settings", build, option_a, option_b)`` adds the options (in help order) and passes the command
``settings=build(**their values)`` in place of one parameter each: the command builds the library's settings
object from the options that set it, and the library never sees a flag.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])


def option_group(dest: str, build: Callable[..., Any], *options: Callable[[Any], Any]) -> Callable[[F], F]:
    """A decorator adding ``options`` (``click.option(...)`` decorators, in help order) whose values go to ``build``;
    the command gets the result as its ``dest`` parameter. ``build`` may raise :class:`~ilic_cli.errors.IlicError`
    naming the option at fault."""

    def decorate(func: F) -> F:
        names: list[str] = []

        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            values = {name: kwargs.pop(name) for name in names}
            return func(*args, **{dest: build(**values)}, **kwargs)

        params = getattr(wrapper, "__click_params__", [])
        before = len(params)
        for option in reversed(options):
            option(wrapper)
        names.extend(p.name for p in getattr(wrapper, "__click_params__", [])[before:])
        return cast(F, wrapper)

    return decorate
