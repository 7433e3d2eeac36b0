"""The tune report's page (csmlab/report/tune_page.py): here, the search space as the page lists it."""

from __future__ import annotations

from csmlab.report.tune_page import space_rows
from csmlab.settings import SETTING_GROUPS

TITLE = {group.name: group.title for group in SETTING_GROUPS}


def test_search_space_is_listed_group_by_group_with_each_fields_group_title():
    space = {"filter_size": ("choice", (3, 5)), "lambda": ("range", 0.2, 0.9, False, None),
             "cascades": ("choice", (2, 4)),
             "bias_slope": ("range", 0.5, 8.0, True, None), "resolution": ("choice", (512, 1024))}
    assert space_rows(space) == [
        (TITLE["maps"], "cascades", "2, 4"), (TITLE["maps"], "resolution", "512, 1024"),
        (TITLE["split"], "lambda", "0.2 … 0.9"), (TITLE["filter"], "filter_size", "3, 5"),
        (TITLE["bias"], "bias_slope", "0.5 … 8.0 (log)")]
