"""Cameras several camera tests use."""

from __future__ import annotations

from tagloc.camera import PinholeEquidistant

#: The left camera of the dupont data set (Kalibr, 1280x1024): image corners reach 87.6 degrees.
DUPONT = PinholeEquidistant(
    width=1280, height=1024, fx=603.924, fy=603.166, cx=665.041, cy=554.34,
    k1=-0.0122741, k2=-0.0100319, k3=0.00752173, k4=-0.00247881,
)  # fmt: skip
