"""``tagloc detect``: check a camera and its calibration on tags, one image at a time.

``tagloc detect IMAGE|DIR|BAG --camera cam.yaml [--tags tags.yaml] [--size 0.16]`` runs each
image through the localizer's tag sensor (:func:`tagloc.eval.tag_check.check_frame`) and prints,
per tag, the pose and its sigma, both IPPE branches, the ambiguity decision and every gate's
value against its limit; it says so when a tag looks mirrored or of another size than the
map's. Into ``--out`` go an overlay per image (``<name>.detect.png``: corners, axes, id, verdict)
and ``detections.json``. An image of another size than the camera file's, or a file that is not
an image, stops it with one line and nothing written (outputs are staged and moved into place
at the end).
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tagloc.cli.options import in_range, positive_int

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

_BAG_SUFFIXES = (".bag", ".mcap", ".db3", ".bz2")


def detect(
    source: Annotated[Path, typer.Argument(help="An image, a directory of images, or a bag.")],
    camera: Annotated[
        Path,
        typer.Option(help="Camera file: Kalibr camchain, ROS camera_calibration or CameraInfo."),
    ],
    tags: Annotated[Path | None, typer.Option(help="Tag map: sizes and poses.")] = None,
    size: Annotated[
        float | None,
        typer.Option(help="Tag size, m (tags the map lacks, or all).", callback=in_range(gt=0)),
    ] = None,
    config: Annotated[
        Path | None, typer.Option(help="localizer.yaml: backend, family, noise, gates.")
    ] = None,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/detect"),
    image_topic: Annotated[str, typer.Option(help="Bag: the image topic.")] = "/camera/image",
    max_frames: Annotated[
        int,
        typer.Option(help="Bag: at most this many frames, evenly spread.", callback=positive_int),
    ] = 20,
) -> None:
    """Check a camera and its calibration on tags: pose, sigma, branches and gates per tag."""
    from tagloc.fileutil import check_outputs
    from tagloc.io.images import load_camera_file
    from tagloc.localize import LocalizeError, load_localizer_config
    from tagloc.localize.config import LocalizerConfig
    from tagloc.tags import load_tag_map, make_detector

    check_outputs(
        {"--out": out},
        directories={"--out": ["detections.json"]},
        inputs={"SOURCE": source, "--camera": camera, "--tags": tags},
    )
    if tags is None and size is None:
        raise LocalizeError("give the tags' size: --tags tags.yaml and/or --size METRES")
    model = load_camera_file(camera)
    cfg = LocalizerConfig() if config is None else load_localizer_config(config)
    tag_map = None if tags is None else load_tag_map(tags)
    detector = make_detector(cfg.tags.backend, cfg.tags.family)

    from tagloc.eval.tag_check import check_frame
    from tagloc.eval.tag_check_overlay import draw_frame_check
    from tagloc.eval.tag_check_report import frame_check_dict, frame_check_lines
    from tagloc.io.images import write_image

    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".detect-", dir=out.parent))
    try:
        frames = []
        for name, image in _images(source, image_topic, max_frames):
            check = check_frame(
                image, model, detector, cfg, tag_map=tag_map, size_m=size, name=name
            )
            write_image(
                staging / f"{Path(name).stem}.detect.png", draw_frame_check(image, check, model)
            )
            frames.append(frame_check_dict(check))
            for line in frame_check_lines(check):
                typer.echo(line)
        if not frames:
            raise LocalizeError(f"{source}: no image found")
        (staging / "detections.json").write_text(json.dumps({"frames": frames}, indent=1) + "\n")
        out.mkdir(parents=True, exist_ok=True)
        for path in sorted(staging.iterdir()):
            path.replace(out / path.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    accepted = sum(t["accepted"] for f in frames for t in f["tags"])
    seen = sum(len(f["tags"]) for f in frames)
    typer.echo(f"{len(frames)} image(s), {seen} tag(s), {accepted} accepted; wrote {out}")


def _images(
    source: Path, image_topic: str, max_frames: int
) -> Iterator[tuple[str, npt.NDArray[np.uint8]]]:
    """``(name, image)`` of an image file, a directory's images, or a bag's image topic."""
    from tagloc.io import InputNotFoundError, is_ros2_bag_directory
    from tagloc.io.images import image_files, read_image

    if not source.exists():
        raise InputNotFoundError(f"{source}: no such file or directory")
    is_bag = source.suffix.lower() in _BAG_SUFFIXES or (
        source.is_dir() and (source / "metadata.yaml").is_file() and is_ros2_bag_directory(source)
    )
    if is_bag:
        yield from _bag_images(source, image_topic, max_frames)
    elif source.is_dir():
        for path in image_files(source):
            yield path.name, read_image(path)
    else:
        yield source.name, read_image(source)


def _bag_images(
    bag: Path, topic: str, max_frames: int
) -> Iterator[tuple[str, npt.NDArray[np.uint8]]]:
    import numpy as np

    from tagloc.io import BagSource, ImageMsg
    from tagloc.localize import LocalizeError

    probe = BagSource(bag)
    if topic not in probe.bag_topics:
        raise LocalizeError(
            f"{bag}: no image topic {topic!r} (topics: {', '.join(sorted(probe.bag_topics))}); "
            "pick one with --image-topic"
        )
    step = max(1, math.ceil(probe.bag_topics[topic].msgcount / max_frames))
    k = 0
    for _, msg in BagSource(bag, [topic]):
        if isinstance(msg, ImageMsg):
            if k % step == 0:
                yield f"frame_{k:06d}_{msg.stamp_ns}", np.asarray(msg.image)
            k += 1
