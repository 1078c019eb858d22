"""``tagloc detect`` on rendered images: the numbers of the tag sweep (the same views through the
same stack), a mirrored and a wrong-size tag named, bad input refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from cli_runner import one_error_line, run_tagloc
from tagloc.eval.tag_sweep import run_tag_sweep
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.eval.tag_views import rotation_error_deg, sample_wall_view
from tagloc.geometry import SE3
from tagloc.sim.render import render_tags_scene
from tagloc.tags import TagEntry, TagMap, family_spec

SWEEP = TagSweepConfig(
    distances_m=(1.0, 3.0),
    angles_deg=(0.0, 30.0, 60.0),
    blur_px=(0.0,),
    noise_dn=(1.5,),
    trials=1,
    prior="none",
    joint_tag_counts=(),
    seed=4,
)


def _camera_file(path: Path, config: TagSweepConfig, width: int | None = None) -> Path:
    """The sweep's camera as a CameraInfo-shaped YAML file (``width`` overrides its width)."""
    cam = config.camera_model()
    info = {
        "width": width or cam.width,
        "height": cam.height,
        "distortion_model": "plumb_bob",
        "D": [0.0] * 5,
        "K": [cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0],
    }
    path.write_text(yaml.safe_dump(info))
    return path


def _sweep_view(config: TagSweepConfig, distance: float, angle: float):  # type: ignore[no-untyped-def]
    """The first view of a sweep cell, drawn as the sweep draws it (its documented seed stream:
    the sweep seed, the cell's values in micro-units, the view index)."""
    blur, noise = config.reference_condition
    seed = [config.seed, *(round(1e6 * v) for v in (distance, angle, blur, noise)), 0]
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    T_cam_tag, T_map_cam = sample_wall_view(distance, np.deg2rad(angle), rng, config.tilt_deg)
    tag_id = int(rng.integers(family_spec(config.family).num_ids))
    render = config.render.model_copy(update={"defocus_sigma_px": blur, "read_noise_dn": noise})
    image, _ = render_tags_scene(
        config.camera_model(),
        [(tag_id, config.tag_size_m, T_cam_tag)],
        render,
        rng,
        background=config.background_albedo,
        family=config.family,
    )
    return image, tag_id, T_cam_tag, T_map_cam


def _detect(tmp: Path, image: np.ndarray, *args: str) -> dict:  # type: ignore[type-arg]
    cv2.imwrite(str(tmp / "view.png"), image)
    done = run_tagloc("detect", str(tmp / "view.png"), "--out", str(tmp / "out"), *args)
    assert done.returncode == 0, done.stderr
    assert (tmp / "out" / "view.detect.png").is_file()
    frames: list[dict] = json.loads((tmp / "out" / "detections.json").read_text())["frames"]  # type: ignore[type-arg]
    return frames[0] | {"stdout": done.stdout}


def test_detect_gives_the_tag_sweeps_numbers(tmp_path: Path) -> None:
    result = run_tag_sweep(SWEEP)
    camera = _camera_file(tmp_path / "cam.yaml", SWEEP)
    localizer = tmp_path / "localizer.yaml"
    localizer.write_text(
        yaml.safe_dump({"tags": {"noise": {"sigma_px": SWEEP.noise_model().sigma_px}}})
    )
    n_accepted = 0
    for row in result.rows:
        image, tag_id, T_cam_tag, T_map_cam = _sweep_view(SWEEP, row.distance_m, row.angle_deg)
        tag_map = TagMap.from_entries([TagEntry.from_pose(tag_id, T_map_cam @ T_cam_tag, 0.16)])
        (tmp_path / "tags.yaml").write_text(tag_map.to_yaml_text())
        frame = _detect(
            tmp_path,
            image,
            "--camera",
            str(camera),
            "--tags",
            str(tmp_path / "tags.yaml"),
            "--config",
            str(localizer),
        )
        ours = [t for t in frame["tags"] if t["id"] == tag_id]
        assert len(ours) == row.n_detected == 1
        tag = ours[0]
        assert tag["accepted"] == (row.n_accepted == 1), (row, tag["refusal"])
        if not tag["accepted"]:
            assert tag["refusal"].split(":")[0] == row.rejections[0][0]
            assert any(not g["passed"] for g in tag["gates"] if g["passed"] is not None)
            continue
        n_accepted += 1
        pose = tag["T_cam_tag"]
        T_est = SE3.from_quat(pose["quat_xyzw"], pose["translation_m"])
        position_error = float(np.linalg.norm(T_est.translation - T_cam_tag.translation))
        assert position_error == pytest.approx(row.position_error_median_m, rel=1e-6, abs=1e-9)
        assert rotation_error_deg(T_cam_tag, T_est) == pytest.approx(
            row.rotation_error_median_deg, rel=1e-6, abs=1e-7
        )
        assert all(g["passed"] in (True, None) for g in tag["gates"])
        assert len(tag["branches"]) == 2 and tag["ambiguity"]["reason"] is None
        assert len(tag["sigma"]) == 6 and all(s > 0 for s in tag["sigma"])
    assert n_accepted >= 3  # the test compares numbers, not only refusals


def _three_tags(size_of_c: float):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(7)
    T_cam_tag, T_map_cam = sample_wall_view(2.0, np.deg2rad(25.0), rng, 1.0)
    offsets = {3: 0.0, 5: 0.45, 7: -0.45}
    poses = {
        i: T_cam_tag @ SE3.from_rotvec([0.0, 0.0, 0.0], [dx, 0.0, 0.0]) for i, dx in offsets.items()
    }
    sizes = {3: 0.16, 5: 0.16, 7: size_of_c}
    image, _ = render_tags_scene(
        SWEEP.camera_model(), [(i, sizes[i], poses[i]) for i in poses], SWEEP.render, rng
    )
    tag_map = TagMap.from_entries(
        [TagEntry.from_pose(i, T_map_cam @ poses[i], 0.16) for i in poses]
    )
    return image, tag_map


def test_a_wrong_size_tag_and_a_mirrored_tag_are_named(tmp_path: Path) -> None:
    camera = _camera_file(tmp_path / "cam.yaml", SWEEP)
    image, tag_map = _three_tags(0.12)
    (tmp_path / "tags.yaml").write_text(tag_map.to_yaml_text())
    frame = _detect(tmp_path, image, "--camera", str(camera), "--tags", str(tmp_path / "tags.yaml"))
    size_notes = [n for n in frame["notes"] if "not the map's" in n]
    assert len(size_notes) == 1 and size_notes[0].startswith("tag 7 looks 0.12 m"), frame["notes"]
    assert "tag 7 looks 0.12 m" in frame["stdout"]
    # the same scene seen in a mirror: every tag named as mirrored, none taken as a tag
    frame = _detect(
        tmp_path, np.ascontiguousarray(image[:, ::-1]), "--camera", str(camera), "--size", "0.16"
    )
    assert frame["tags"] == [] and sorted(m["id"] for m in frame["mirrored"]) == [3, 5, 7]
    assert sum("is mirrored" in n for n in frame["notes"]) == 3


def test_bad_input_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    camera = _camera_file(tmp_path / "cam.yaml", SWEEP)
    other = _camera_file(tmp_path / "other.yaml", SWEEP, width=640)
    image, _ = _three_tags(0.16)
    cv2.imwrite(str(tmp_path / "view.png"), image)
    (tmp_path / "notes.png").write_text("not an image\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    out = tmp_path / "out"
    for args, words in (
        ((str(tmp_path / "notes.png"), "--camera", str(camera)), "notes.png: not an image"),
        (
            (str(tmp_path / "view.png"), "--camera", str(other)),
            "1280x720 px but the camera file is for 640x720",
        ),
        ((str(tmp_path), "--camera", str(camera)), "notes.png: not an image"),  # a directory
        ((str(tmp_path / "view.png"), "--camera", str(tmp_path / "view.png")), "camera"),
    ):
        line = one_error_line(run_tagloc("detect", *args, "--size", "0.16", "--out", str(out)))
        assert words in line, line
        assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_detect_reads_the_images_of_a_bag(tmp_path: Path) -> None:
    from tagloc.io import BagSink, ImageMsg

    camera = _camera_file(tmp_path / "cam.yaml", SWEEP)
    image, tag_map = _three_tags(0.16)
    (tmp_path / "tags.yaml").write_text(tag_map.to_yaml_text())
    bag = tmp_path / "drive.mcap"
    with BagSink(bag, "mcap") as sink:
        for k in range(4):
            sink.write("/camera/image", ImageMsg(10**9 * (k + 1), "camera_optical", image, "mono8"))
    out = tmp_path / "out"
    done = run_tagloc(
        "detect",
        str(bag),
        "--camera",
        str(camera),
        "--tags",
        str(tmp_path / "tags.yaml"),
        "--max-frames",
        "2",
        "--out",
        str(out),
    )
    assert done.returncode == 0, done.stderr
    frames = json.loads((out / "detections.json").read_text())["frames"]
    assert [f["image"].split("_")[1] for f in frames] == ["000000", "000002"]  # every other frame
    for frame in frames:
        assert sorted(t["id"] for t in frame["tags"]) == [3, 5, 7]
        assert not any("not the map's" in n for n in frame["notes"])  # all of the map's size
    assert len(list(out.glob("frame_*.detect.png"))) == 2
    line = one_error_line(
        run_tagloc(
            "detect",
            str(bag),
            "--camera",
            str(camera),
            "--size",
            "0.16",
            "--image-topic",
            "/nope",
            "--out",
            str(tmp_path / "o2"),
        )
    )
    assert "/nope" in line and "/camera/image" in line and not (tmp_path / "o2").exists()
