"""The lacking rules every engine module shares (csmlab/engines/common.py): here, how lacking lines are grouped."""

from __future__ import annotations

from csmlab.engines.common import OTHER_TITLE, in_group_order, lacking_by_group
from csmlab.settings import SETTING_GROUPS

TITLE = {group.name: group.title for group in SETTING_GROUPS}


def test_lacking_lines_are_headed_by_the_group_of_the_first_field_they_name_in_documented_order():
    lines = ["storage = 'array' (atlas)", "split distances rounded (no field named)", "stabilization = 'none'",
             "bias_constant = 0.0, bias_slope = 2.0 (units)", "cascades = 3 (2 written)", "fit = 'sphere'",
             "unknown_knob = 1 (not a [shadow] field)"]
    assert lacking_by_group(lines) == [
        (TITLE["maps"], ("cascades = 3 (2 written)",)),
        (TITLE["fit"], ("fit = 'sphere'", "stabilization = 'none'")),
        (TITLE["bias"], ("bias_constant = 0.0, bias_slope = 2.0 (units)",)),
        (TITLE["storage"], ("storage = 'array' (atlas)",)),
        (OTHER_TITLE, ("split distances rounded (no field named)", "unknown_knob = 1 (not a [shadow] field)"))]


def test_group_order_keeps_every_line_once_and_no_lines_give_no_groups():
    lines = ["blend_curve = 'linear'", "blend_band = 0.1 (x)", "cascades = 3", "lambda = 0.5", "blend_band = 0.2 (y)"]
    assert in_group_order(lines) == ("cascades = 3", "lambda = 0.5", "blend_band = 0.1 (x)", "blend_band = 0.2 (y)",
                                     "blend_curve = 'linear'")
    assert lacking_by_group([]) == [] and in_group_order(()) == ()
