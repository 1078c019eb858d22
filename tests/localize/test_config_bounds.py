"""localizer.yaml: values that would hang or overflow the filter are refused with one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from tagloc.errors import ConfigError
from tagloc.localize import LocalizerConfig, load_localizer_config


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "process_noise:\n  motion_step_s: 1.0e-9\n",
            "process_noise.motion_step_s: input should be greater than or equal to 0.005",
        ),
        (
            "filter:\n  history_size: 18446744073709551615\n",
            "filter.history_size: input should be less than or equal to 10000000",
        ),
        (
            "filter:\n  max_iterations: 1000000000\n",
            "filter.max_iterations: input should be less than or equal to 20",
        ),
        (
            "process_noise:\n  sigma_per_sqrt_m: [1.0e300, 0, 0, 0, 0, 0]\n",
            "process_noise.sigma_per_sqrt_m[0]: input should be less than or equal to 1000",
        ),
    ],
)
def test_unbounded_values_are_refused(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "localizer.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_localizer_config(path)
    assert str(info.value) == f"{path}: {expected}"


def test_non_utf8_localizer_names_file_and_offset(tmp_path: Path) -> None:
    path = tmp_path / "localizer.yaml"
    path.write_bytes(b"frames:\n  map_frame: m\xe4p\n")
    with pytest.raises(ConfigError) as info:
        load_localizer_config(path)
    assert str(info.value) == (
        f"{path}: localizer config is not UTF-8 text: byte 0xe4 at offset 22"
    )


def test_huge_windows_and_distances_are_refused_not_overflowed() -> None:
    text = "gates:\n  consistency_window_s: 1.0e+300\nkidnap:\n  window_s: 1.0e+300\n"
    with pytest.raises(ConfigError) as info:
        LocalizerConfig.from_yaml_text(text, "localizer.yaml")
    assert str(info.value) == (
        "localizer.yaml: gates.consistency_window_s: input should be less than or equal to "
        "1000000 (and 1 more error)"
    )
