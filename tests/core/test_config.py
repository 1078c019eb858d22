"""Strict YAML parsing and one-line validation errors shared by every config file."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import Field, field_validator

from tagloc.config import (
    MAX_QUOTED_CHARS,
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    StrictModel,
    parse_yaml_mapping,
    read_text_file,
    short_repr,
    validate,
)
from tagloc.errors import ConfigError
from tagloc.tags import TagMapError


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


# ----- bounded reading and parsing --------------------------------------------------------------
def _alias_bomb(levels: int) -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def test_alias_expansion_past_the_limit_is_refused_without_expanding() -> None:
    text = _alias_bomb(9)  # 9**9 values once expanded, from 500 bytes; 9**7 passes the limit
    with pytest.raises(ConfigError) as info:
        parse_yaml_mapping(text, "bomb.yaml")
    assert str(info.value) == (
        f"bomb.yaml: line 7, column 5: invalid YAML: expands to more than {MAX_YAML_NODES} "
        "values through aliases (*name)"
    )


def test_shared_aliases_below_the_limit_are_fine() -> None:
    data = parse_yaml_mapping(_alias_bomb(3), "ok.yaml")
    assert len(data["a2"]) == 9 and data["a2"][8][8] == ["x"] * 9


def test_cyclic_alias_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"^c\.yaml: line 1, column 7: .*a cycle"):
        parse_yaml_mapping("tags: &a [*a]\n", "c.yaml")


@pytest.mark.parametrize("flow", [True, False])
def test_deep_nesting_is_one_line_not_a_recursion_error(flow: bool) -> None:
    depth = MAX_YAML_DEPTH + 5 if not flow else 5000
    if flow:
        text = "tags: " + "[" * depth + "]" * depth + "\n"
    else:
        text = "tags:\n" + "".join("  " * (k + 1) + "- \n" for k in range(depth))
    with pytest.raises(ConfigError) as info:
        parse_yaml_mapping(text, "deep.yaml")
    message = str(info.value)
    assert message.startswith("deep.yaml: line ") and "\n" not in message
    assert "nesting depth" in message if flow else f"deeper than {MAX_YAML_DEPTH}" in message


def test_overlong_text_is_refused_before_parsing() -> None:
    with pytest.raises(ConfigError, match=r"^big\.yaml: longer than \d+ characters"):
        parse_yaml_mapping("a: " + "x" * MAX_YAML_BYTES, "big.yaml")


def test_read_text_file_names_file_and_byte_offset_of_bad_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes("version: 1\nname: caf\xe9\n".encode("latin-1"))
    with pytest.raises(ConfigError) as info:
        read_text_file(path, "world file")
    assert str(info.value) == f"{path}: world file is not UTF-8 text: byte 0xe9 at offset 20"


def test_read_text_file_refuses_large_files_and_directories(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    path.write_bytes(b"a" * 101)
    with pytest.raises(TagMapError, match=r"big\.yaml: tag map is larger than 100 bytes"):
        read_text_file(path, "tag map", max_bytes=100, error=TagMapError)
    assert read_text_file(path, "tag map", max_bytes=101) == "a" * 101
    with pytest.raises(ConfigError, match=r": cannot read world file: Is a directory$"):
        read_text_file(tmp_path, "world file")


def test_short_repr_quotes_a_prefix_without_building_the_whole_repr() -> None:
    huge = [["x" * 1000] * 1000] * 1000  # a billion characters if repr'd in full
    text = short_repr(huge)
    assert len(text) <= MAX_QUOTED_CHARS and text.endswith("...")
    assert short_repr("abc") == "'abc'"


def test_validation_messages_quote_only_a_prefix_of_a_bad_value() -> None:
    text = "version: 1\nitems: [{id: 1, size: 1}]\nextra: [" + ", ".join(["long"] * 5000) + "]\n"
    with pytest.raises(ConfigError) as info:
        validate(_Checked, parse_yaml_mapping(text, "f"), "f.yaml")
    assert len(str(info.value)) < 300
    assert str(info.value).startswith("f.yaml: extra: bad ['long', 'long'")


class _Checked(StrictModel):
    version: int
    items: tuple[_Item, ...]
    extra: list[str]

    @field_validator("extra")
    @classmethod
    def _never(cls, value: list[str]) -> list[str]:
        raise ValueError(f"bad {value!r}")  # a validator that quotes the whole value
