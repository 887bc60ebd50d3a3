"""Command-line KEY=VALUE options: values read as Python literals or text, bad options named."""

from __future__ import annotations

import pytest

from mpg_agents.evaluation.env_options import literal_or_text, parse_env_option, parse_env_options


@pytest.mark.parametrize(
    "raw, value",
    [("3", 3), (" 0.5 ", 0.5), ("True", True), ("(0, 0.3)", (0, 0.3)), ("camera", "camera"), (" fail ", "fail"), ("", "")],
)
def test_a_value_is_a_literal_where_it_is_one_else_text(raw, value):
    assert literal_or_text(raw) == value


def test_env_options_are_parsed_and_bad_ones_named():
    assert parse_env_option("visible_range=(0, 0.3)") == ("visible_range", (0, 0.3))
    assert parse_env_options(["wrong_grasp=fail"]) == {"wrong_grasp": "fail"}
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_env_option("wrong_grasp")
    with pytest.raises(ValueError, match="--num-objects"):
        parse_env_option("num_objects=3")
    with pytest.raises(ValueError, match="given twice"):
        parse_env_options(["wrong_grasp=fail", "wrong_grasp=fail"])
    with pytest.raises(ValueError, match="not an env keyword"):
        parse_env_options(["no_such_option=1"])


def test_the_speed_benchmarks_net_options_go_over_the_shipped_config(benchmark_script):
    shipped_net_config = benchmark_script("td_step_speed").shipped_net_config
    base = shipped_net_config([])
    assert base["color_input"] is False  # the shipped nets are colour-free
    assert shipped_net_config(["color_input=True", "grasp_region=rectangle"]) == {**base, "color_input": True, "grasp_region": "rectangle"}
    for bad in ("colr_input=True", "color_input"):
        with pytest.raises(ValueError, match="MPGNetConfig field"):
            shipped_net_config([bad])
