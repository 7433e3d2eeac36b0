"""The one protocol of every ``*_METHODS`` table: a name check and a dispatch by declared parameters.

A registry is a dict from a name (the value a TOML field or a keyword takes) to what it names: a
function, a record or an integer code a kernel switches on. :func:`check_name` refuses a name that
is not a key with one message, the same from the config loader and from Python callers: the field,
the valid names and the closest one (``split: expected one of [...], got 'practcal' (did you mean
'practical'?)``). :func:`dispatch` calls a registered function with only the keywords it declares,
so a method's signature is its contract and no method swallows keywords it does not use.

This module imports neither Warp nor NumPy: the config loader checks names without loading kernels.
"""

from __future__ import annotations

import difflib
import functools
import inspect
from collections.abc import Callable, Mapping

__all__ = ["check_name", "close_match_hint", "dispatch", "parameters", "unknown_name_message"]


def close_match_hint(value, names) -> str:
    """`` (did you mean 'x'?)`` for the name in ``names`` closest to ``value``; empty when none is close."""
    close = difflib.get_close_matches(str(value), [str(n) for n in names], n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def unknown_name_message(value, registry: Mapping) -> str:
    """What was expected instead of ``value``: the registry's names, sorted, and the closest one."""
    return f"expected one of {sorted(registry)}, got {value!r}{close_match_hint(value, registry)}"


def check_name(value, registry: Mapping, *, field: str) -> str:
    """Return ``value`` if it names an entry of ``registry``.

    Raises
    ------
    ValueError
        ``"<field>: expected one of [...], got '<value>' (did you mean '<name>'?)"``.
    """
    if isinstance(value, str) and value in registry:
        return value
    raise ValueError(f"{field}: {unknown_name_message(value, registry)}")


@functools.cache
def parameters(function: Callable) -> tuple[str, ...]:
    """The keyword parameters ``function`` declares, in order.

    Raises
    ------
    TypeError
        If it takes ``**kwargs``: a registered method declares what it reads.
    """
    declared = inspect.signature(function).parameters.values()
    if any(p.kind is p.VAR_KEYWORD for p in declared):
        raise TypeError(f"{function.__qualname__}: a registered method declares its keywords, not **kwargs")
    return tuple(p.name for p in declared if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD))


def dispatch(registry: Mapping[str, Callable], name: str, /, *args, field: str, offered: Mapping | None = None,
             **params):
    """``registry[name](*args, **params, **(the offered keywords it declares))``.

    Parameters
    ----------
    registry : mapping of str to callable
        A ``*_METHODS`` table.
    name : str
        The method, checked with :func:`check_name`.
    *args
        Positional arguments every method takes.
    field : str
        Names the choice in messages (``split``, ``camera.path``).
    offered : mapping, optional
        Keywords some methods of the registry take: each is passed to the method if it declares it.
    **params
        Keywords the chosen method must declare.

    Raises
    ------
    ValueError
        On an unknown name, or a keyword in ``params`` the method does not declare (listing those it does).
    TypeError
        On an offered keyword that no method of the registry declares (a misspelt keyword in the caller).
    """
    function = registry[check_name(name, registry, field=field)]
    declared = parameters(function)
    unknown = sorted(set(params) - set(declared))
    if unknown:
        raise ValueError(f"{name}: unknown parameter(s) {unknown}; expected some of {sorted(declared)}")
    offered = dict(offered or {})
    anywhere = {p for f in registry.values() for p in parameters(f)}
    stray = sorted(set(offered) - anywhere)
    if stray:
        raise TypeError(f"{field}: no method of the registry takes {stray}")
    return function(*args, **params, **{k: v for k, v in offered.items() if k in declared})
