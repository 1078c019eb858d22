"""The documented file examples are real: the tags.yaml of docs/file-formats.md loads, its
localizer.yaml is the defaults."""

from __future__ import annotations

import re
from pathlib import Path

from tagloc.localize import LocalizerConfig
from tagloc.tags import TagMap

DOC = (Path(__file__).resolve().parents[2] / "docs" / "file-formats.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"```yaml\n(.*?)```", DOC, re.S)


def test_the_tag_map_example_loads() -> None:
    (text,) = [b for b in BLOCKS if b.startswith("# tagloc tag map")]
    tag_map = TagMap.from_yaml_text(text, "README tags.yaml")
    assert sorted(tag_map.ids()) == [0, 1, 40]
    assert [e.id for e in tag_map.anchors] == [1]
    assert tag_map.get(40) is not None and tag_map.get(40).frame == "elevator_cab"  # type: ignore[union-attr]


def test_the_localizer_example_is_the_defaults() -> None:
    (text,) = [b for b in BLOCKS if b.startswith("version: 1\nframes: {map_frame")]
    assert LocalizerConfig.from_yaml_text(text, "README localizer.yaml") == LocalizerConfig()
