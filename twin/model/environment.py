"""Choosing a track: a built-in name or a PNG file."""

from __future__ import annotations

import os

import numpy as np

from mjcf import track as track_mod
from lf_common.errors import InputTooLarge
from mjcf.maze import maze_track
from mjcf.track import MAX_TEXTURE_PIXELS, FloorTexture, Track
from mjcf.track_image import track_from_png
from twin.errors import TwinError


def load_track(
    name_or_path: str,
    line_width: float,
    texture_resolution: float,
    metres_per_pixel: float | None = None,
) -> tuple[Track, FloorTexture]:
    """A track and its floor texture.

    Args:
      name_or_path: a built-in track name, or a path to an image (``*.png``; any other name of an existing file is
        read, and checked, as one).
      line_width: line width in [m] for built-in tracks (an image's is measured).
      texture_resolution: pixel pitch in [m] for rasterising built-in tracks.
      metres_per_pixel: an image's scale in [m], when it has no DPI metadata.
    """
    builtin = name_or_path == "maze" or name_or_path in track_mod.BUILTIN_SEGMENTS
    if (name_or_path.lower().endswith((".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")) or os.sep in name_or_path
            or (not builtin and os.path.lexists(name_or_path))):
        track, texture = track_from_png(name_or_path, metres_per_pixel=metres_per_pixel)
        return track, _padded(texture, margin_m=0.3)
    if name_or_path == "maze":
        maze = maze_track(line_width)
        return maze, maze.rasterise(metres_per_pixel=texture_resolution)
    if not builtin:
        raise TwinError(
            f"track {name_or_path!r}: unknown track; built-in tracks are {', '.join(track_mod.BUILTIN_SEGMENTS)}, "
            "maze, or give a PNG file"
        )
    centre_track = track_mod.builtin(name_or_path)
    track = Track(centre_track.name, centre_track.centre, line_width_m=line_width)
    return track, track.rasterise(metres_per_pixel=texture_resolution)


def _padded(texture: FloorTexture, margin_m: float) -> FloorTexture:
    """Pad an image with plain ground so a robot near its edge stays on the (finite) floor."""
    pad = int(round(margin_m / texture.metres_per_pixel))
    h, w = (n + 2 * pad for n in texture.grey.shape)
    if w * h > MAX_TEXTURE_PIXELS:
        raise InputTooLarge(f"track image: with the {margin_m:g} m floor margin around it the texture is {w}×{h} px, more than "
                            f"the {MAX_TEXTURE_PIXELS / 1e6:g} megapixel limit; downsample the image")
    ground = int(np.percentile(texture.grey, 90))
    grey = np.pad(texture.grey, pad, mode="constant", constant_values=ground)
    ox, oy = texture.origin_xy
    return FloorTexture(grey, (ox - pad * texture.metres_per_pixel, oy - pad * texture.metres_per_pixel), texture.metres_per_pixel)
