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


@pytest.mark.parametrize(
    ("text", "field", "words"),
    [
        ("tags: {noise: {sigma_px: .inf}}", "tags.noise.sigma_px", "input should be a finite"),
        ("tags: {noise: {sigma_px: 1.0e-300}}", "tags.noise.sigma_px", "must be at least 0.001"),
        ("tags: {noise: {floor_translation_m: .inf}}", "floor_translation_m", "should be a finite"),
        ("tags: {noise: {view_angle_gain: 1.0e300}}", "view_angle_gain", "input should be less"),
        ("tags: {family: tag99h99}", "tags.family", "unknown tag family 'tag99h99'"),
        ("gates: {max_hamming: 1000000000}", "gates.max_hamming", "input should be less"),
        ("gates: {prior_gate_chi2: .inf}", "gates.prior_gate_chi2", "input should be a finite"),
        ("kidnap: {n_fixes: 3, min_sources: 5}", "kidnap.min_sources", "must be at most n_fixes"),
        ("supervisor: {camera: {timeout_s: 0.01}}", "camera.timeout_s", "must be above the period"),
        ("supervisor: {ladder: {enter_nis: 1.0e300}}", "ladder.enter_nis", "input should be less"),
        ("lidar: {fix: {min_range_m: 50}}", "lidar.fix.min_range_m", "must be below max_range_m"),
        ("lidar: {fix: {registration: {num_threads: 100000}}}", "num_threads", "equal to 64"),
        ("lidar: {fix: {registration: {max_iterations: 1.0e9}}}", "max_iterations", "input"),
        ("lidar: {fix: {registration: {num_neighbors: 1000000000}}}", "num_neighbors", "less"),
        ("lidar: {fix: {registration: {voxel_m: 1.0e-9}}}", "voxel_m", "should be greater"),
        ("lidar: {fix: {covariance_inflation: 1.0e300}}", "covariance_inflation", "should be less"),
    ],
)
def test_every_section_refuses_values_out_of_range_or_order(
    tmp_path: Path, text: str, field: str, words: str
) -> None:
    """Values that native code cannot take (threads, neighbours), that overflow (infinite noise,
    a tiny sigma) or that silently change the behaviour (a minimum above its maximum, a timeout
    shorter than the input's period) are one line naming the file and the field."""
    path = tmp_path / "localizer.yaml"
    path.write_text(text + "\n")
    with pytest.raises(ConfigError) as info:
        load_localizer_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert f"{field}: " in message and words in message.partition(f"{field}: ")[2]
