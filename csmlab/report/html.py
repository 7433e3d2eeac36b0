"""The report page: ``templates/report.html`` rendered with Jinja2.

The page is self-contained apart from the files beside it (relative links, no network
resource, inline CSS; the scripts of the interactive part are in ``explore/``) and depends on its
context only, so the same results give byte-identical HTML.
"""

from __future__ import annotations

from pathlib import Path

import jinja2

__all__ = ["render_report_html"]

_TEMPLATES = Path(__file__).parent / "templates"


def render_report_html(context: dict, *, template: str = "report.html") -> str:
    """The report page as HTML text.

    Parameters
    ----------
    context : dict
        The template's variables (see ``templates/report.html``); missing ones are an error.
    template : str
        A file of ``templates/`` (``tune.html`` is the tune report).

    Raises
    ------
    jinja2.UndefinedError
        If the template uses a variable that ``context`` lacks.
    """
    environment = jinja2.Environment(
        loader=jinja2.FileSystemLoader(_TEMPLATES),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    return environment.get_template(template).render(**context)
