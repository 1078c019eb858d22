"""Strict YAML parsing and one-line validation errors shared by every config file."""

from __future__ import annotations

import pytest
from pydantic import Field

from tagloc.config import StrictModel, parse_yaml_mapping, validate
from tagloc.errors import ConfigError


class _Item(StrictModel):
    id: int
    size: float = Field(gt=0)


class _File(StrictModel):
    version: int
    items: tuple[_Item, ...]


def test_duplicate_keys_are_rejected_with_both_lines() -> None:
    text = "version: 1\nitems: []\nversion: 2\n"
    with pytest.raises(ConfigError) as info:
        parse_yaml_mapping(text, "a.yaml")
    assert str(info.value) == (
        "a.yaml: line 3, column 1: invalid YAML: duplicate key 'version' (first at line 1)"
    )


def test_nested_duplicate_keys_are_rejected() -> None:
    with pytest.raises(ConfigError, match=r"line 2, .*duplicate key 'id'"):
        parse_yaml_mapping("items:\n  - {id: 1, id: 2}\n", "b.yaml")


@pytest.mark.parametrize("text", ["- 1\n- 2\n", "just text\n", ""])
def test_top_level_must_be_a_mapping(text: str) -> None:
    with pytest.raises(ConfigError, match=r"c\.yaml: the top level must be a mapping"):
        parse_yaml_mapping(text, "c.yaml")


def test_validation_error_names_the_field_path_on_one_line() -> None:
    data = parse_yaml_mapping("version: 1\nitems:\n  - {id: 1, size: 0.1}\n  - {id: 2}\n", "d")
    with pytest.raises(ConfigError) as info:
        validate(_File, data, "d.yaml")
    assert str(info.value) == "d.yaml: items[1].size: field required"
    data = parse_yaml_mapping("version: 1\nitems: [{id: 1, size: -1}]\nextra: 3\n", "e")
    with pytest.raises(ConfigError) as info:
        validate(_File, data, "e.yaml")
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("e.yaml: items[0].size: input should be greater than 0")
    assert str(info.value).endswith("(and 1 more error)")
