"""The ROS map_server file format: a YAML description next to a PGM or PNG image.

Loading follows ROS 1 map_server (image_loader.cpp) value for value:
  - the channels of a pixel are averaged (for a colour image; in trinary mode an alpha channel is
    averaged in too, as ROS does); with `negate` the average is replaced by 255 − average;
  - p = (255 − average) / 255 is the occupancy probability;
  - trinary: p > occupied_thresh → 100, p < free_thresh → 0, otherwise −1 (unknown);
  - scale: as trinary, but in between → int(1 + 98·(p − free_thresh)/(occupied_thresh − free_thresh)),
    or −1 where the pixel is fully transparent;
  - raw: the (negated) average itself when it is 0..100, otherwise −1. ROS 1 wraps larger values
    into int8 (so 255 becomes −1 there too); mapping every other value to −1 is what nav2 does.
Palette images are read by their colours (ROS 1 would read the palette indices).

The image's row 0 is the TOP of the map; OccupancyGrid.data's row 0 is the row at the origin.

Cells and the world: geometry/grid.py.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from PIL import Image

from ...schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D

MODES = ("trinary", "scale", "raw")
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
# The greys ROS map_saver writes; they load back as 100 / 0 / −1 with the default thresholds.
OCCUPIED_GREY, FREE_GREY, UNKNOWN_GREY = 0, 254, 205
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_WHITESPACE = b" \t\r\n\x0b\x0c"


class MapError(ValueError):
    """A map file that is missing, malformed or unreadable; the message names the file and key."""


def read_yaml(path: Path, error: type[Exception] = MapError) -> dict:
    """A YAML file that must hold a mapping; `error` is raised (naming the file) otherwise."""
    if not path.is_file():
        raise error(f"{path}: no such file")
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise error(f"{path}: expected a mapping of keys to values, got {type(data).__name__}")
    return data


@dataclass(frozen=True)
class MapFile:
    """The contents of a map YAML file; `image` is resolved against the YAML file's folder."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str = "trinary"


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)


def read_map_yaml(path: str | Path) -> MapFile:
    path = Path(path)
    doc = read_yaml(path)
    missing = [key for key in REQUIRED_KEYS if key not in doc]
    if missing:
        raise MapError(f"{path}: missing key {missing[0]!r} (a map needs {', '.join(REQUIRED_KEYS)})")

    def bad(key: str, expected: str):
        return MapError(f"{path}: key {key!r}: expected {expected}, got {doc[key]!r}")

    if not isinstance(doc["image"], str) or not doc["image"]:
        raise bad("image", "the image file name")
    if not _is_number(doc["resolution"]) or doc["resolution"] <= 0:
        raise bad("resolution", "a positive number (m per cell)")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3 or not all(map(_is_number, origin)):
        raise bad("origin", "[x, y, yaw] (three numbers)")
    if doc["negate"] not in (0, 1) or isinstance(doc["negate"], float):
        raise bad("negate", "0 or 1")
    for key in ("occupied_thresh", "free_thresh"):
        if not _is_number(doc[key]) or not 0.0 <= doc[key] <= 1.0:
            raise bad(key, "a number between 0 and 1")
    if doc["free_thresh"] > doc["occupied_thresh"]:
        raise bad("free_thresh", f"at most occupied_thresh ({doc['occupied_thresh']})")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise bad("mode", " | ".join(MODES))
    return MapFile(image=path.parent / doc["image"], resolution=float(doc["resolution"]),
                   origin=tuple(float(v) for v in origin), negate=bool(doc["negate"]),
                   occupied_thresh=float(doc["occupied_thresh"]),
                   free_thresh=float(doc["free_thresh"]), mode=mode)


# ---------------------------------------------------------------- images

def parse_pgm(data: bytes, name: str) -> np.ndarray:
    """An 8-bit PGM (binary P5 or ascii P2) as a (height, width) uint8 array, scaled to 0..255."""
    magic, pos, tokens = data[:2], 2, []
    while len(tokens) < 3:  # width, height, maxval; '#' comments may sit between them
        while pos < len(data) and (data[pos] in _WHITESPACE or data[pos] == ord("#")):
            if data[pos] == ord("#"):
                end = data.find(b"\n", pos)
                pos = len(data) if end < 0 else end
            pos += 1
        start = pos
        while pos < len(data) and data[pos] not in _WHITESPACE and data[pos] != ord("#"):
            pos += 1
        if start == pos:
            raise MapError(f"{name}: truncated PGM header")
        tokens.append(data[start:pos])
    try:
        width, height, maxval = (int(t) for t in tokens)
    except ValueError:
        raise MapError(f"{name}: PGM header is not 'width height maxval': {tokens}") from None
    if width <= 0 or height <= 0:
        raise MapError(f"{name}: PGM size {width} x {height} is empty")
    if not 0 < maxval <= 255:
        raise MapError(f"{name}: PGM maxval {maxval}: only 8-bit images (maxval 1..255) are supported")
    need = width * height
    if magic == b"P5":
        raster = data[pos + 1:pos + 1 + need]  # exactly one whitespace byte ends the header
        if len(raster) < need:
            raise MapError(f"{name}: truncated: {len(raster)} of {need} pixels present")
        pixels = np.frombuffer(raster, np.uint8).astype(np.int64)
    else:
        words = data[pos:].split()
        if len(words) < need:
            raise MapError(f"{name}: truncated: {len(words)} of {need} pixels present")
        try:
            pixels = np.array([int(w) for w in words[:need]], np.int64)
        except ValueError:
            raise MapError(f"{name}: P2 pixel data holds something that is not a number") from None
        if pixels.min() < 0 or pixels.max() > maxval:
            raise MapError(f"{name}: P2 pixel values outside 0..{maxval}")
    if maxval < 255:
        pixels = pixels * 255 // maxval  # as SDL_image stretches low-maxval PGMs
    return pixels.astype(np.uint8).reshape(height, width)


def read_image(path: Path, where: str = "") -> tuple[np.ndarray, bool]:
    """Pixels as (height, width, channels) uint8 and whether the last channel is alpha."""
    name = where or str(path)
    if not path.is_file():
        raise MapError(f"{name}: no such file")
    data = path.read_bytes()
    if data[:2] in (b"P5", b"P2"):
        return parse_pgm(data, name)[:, :, None], False
    if data[:8] != PNG_SIGNATURE:
        raise MapError(f"{name}: not a PGM (P5/P2) or PNG image")
    try:
        with Image.open(path) as image:
            image.load()
            if image.mode == "P":
                image = image.convert("RGBA" if "transparency" in image.info else "RGB")
            elif image.mode == "1":
                image = image.convert("L")
            mode = image.mode
            pixels = np.asarray(image) if mode in ("L", "LA", "RGB", "RGBA") else None
    except (OSError, SyntaxError) as exc:
        raise MapError(f"{name}: unreadable PNG ({exc})") from None
    if pixels is None:
        raise MapError(f"{name}: PNG mode {mode} is not supported (8-bit L, LA, RGB or RGBA only)")
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return pixels, mode in ("LA", "RGBA")


def write_pgm(path: Path, pixels: np.ndarray) -> None:
    height, width = pixels.shape
    header = f"P5\n# omninav map\n{width} {height}\n255\n".encode()
    path.write_bytes(header + np.ascontiguousarray(pixels, np.uint8).tobytes())


# ---------------------------------------------------------------- values

def classify(average: np.ndarray, alpha: np.ndarray | None, mode: str, negate: bool,
             occupied_thresh: float, free_thresh: float) -> np.ndarray:
    """Occupancy values (int8) from averaged pixel values, with ROS 1 map_server's rules."""
    average = np.asarray(average, np.float64)
    if negate:
        average = 255.0 - average
    if mode == "raw":
        value = np.trunc(average)
        return np.where((value >= 0) & (value <= 100), value, -1).astype(np.int8)
    p = (255.0 - average) / 255.0
    out = np.full(p.shape, -1, np.int8)
    if mode == "scale":
        span = occupied_thresh - free_thresh
        band = 1.0 + 98.0 * (p - free_thresh) / span if span > 0 else np.ones_like(p)
        opaque = np.ones(p.shape, bool) if alpha is None else np.asarray(alpha) > 0
        inside = opaque & (p >= free_thresh) & (p <= occupied_thresh)
        out[inside] = np.trunc(band[inside]).astype(np.int8)
    out[p > occupied_thresh] = 100
    out[p < free_thresh] = 0
    return out


def grid_from_pixels(pixels: np.ndarray, has_alpha: bool, spec: MapFile) -> np.ndarray:
    """The OccupancyGrid data (row 0 at the origin) for an image as `read_image` returns it."""
    colour = pixels[:, :, :-1] if has_alpha and spec.mode != "trinary" else pixels
    average = colour.astype(np.float64).sum(axis=2) / colour.shape[2]
    alpha = pixels[:, :, -1] if has_alpha else None
    values = classify(average, alpha, spec.mode, spec.negate, spec.occupied_thresh, spec.free_thresh)
    return np.ascontiguousarray(values[::-1])


def load_map(path: str | Path) -> OccupancyGrid:
    """Load a map_server YAML and its image into an OccupancyGrid (frame 'map')."""
    path = Path(path)
    spec = read_map_yaml(path)
    pixels, has_alpha = read_image(spec.image, where=f"{path}: image {spec.image}")
    data = grid_from_pixels(pixels, has_alpha, spec)
    x, y, yaw = spec.origin
    info = MapMetaData(resolution=spec.resolution, width=data.shape[1], height=data.shape[0],
                       origin=Pose2D(x, y, yaw))
    return OccupancyGrid(header=Header(frame_id="map"), info=info, data=data)


def _pixels_for(data: np.ndarray, mode: str, occupied_thresh: float, free_thresh: float) -> np.ndarray:
    """Greys (and, for scale, alpha) that load back as `data` under the given mode and thresholds."""
    data = np.asarray(data, np.int16)
    if mode == "raw":
        return np.where(data >= 0, data, 255).astype(np.uint8)
    if mode == "trinary":
        p = data / 100.0
        cls = np.where(data < 0, -1, np.where(p > occupied_thresh, 100, np.where(p < free_thresh, 0, -1)))
        table = {100: OCCUPIED_GREY, 0: FREE_GREY, -1: UNKNOWN_GREY}
        loads_as = classify(np.array(list(table.values())), None, mode, False, occupied_thresh, free_thresh)
        if list(loads_as) != list(table):
            raise ValueError(f"thresholds occupied={occupied_thresh} free={free_thresh} cannot "
                             "represent occupied, free and unknown in trinary mode")
        out = np.full(data.shape, UNKNOWN_GREY, np.uint8)
        out[cls == 100], out[cls == 0] = OCCUPIED_GREY, FREE_GREY
        return out
    # scale: each value 0..100 gets the opaque grey that loads nearest to it; unknown is transparent
    loads_as = classify(np.arange(256), None, mode, False, occupied_thresh, free_thresh).astype(np.int16)
    grey_for = np.abs(loads_as[None, :] - np.arange(101)[:, None]).argmin(axis=1).astype(np.uint8)
    grey = np.where(data >= 0, grey_for[np.clip(data, 0, 100)], UNKNOWN_GREY).astype(np.uint8)
    alpha = np.where(data >= 0, 255, 0).astype(np.uint8)
    return np.stack([grey, alpha], axis=-1)


def _replace_atomically(path: Path, write) -> None:
    """Write through a temporary file in the same folder so a failure never leaves half a map."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    os.close(fd)
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)   # mkstemp makes owner-only files; a saved map is for everyone
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def map_files(target: str | Path, mode: str = "trinary") -> tuple[Path, Path]:
    """The YAML and image files `save_map(grid, target, mode)` writes."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    target = Path(target)
    stem = target.with_suffix("") if target.suffix in (".yaml", ".yml") else target
    return stem.parent / f"{stem.name}.yaml", stem.parent / f"{stem.name}.{'png' if mode == 'scale' else 'pgm'}"


def save_map(grid: OccupancyGrid, target: str | Path, mode: str = "trinary",
             occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> Path:
    """Write `target`.yaml and its image, as map_saver -f does; returns the YAML path.

    trinary and raw write an 8-bit P5 PGM; scale writes a grey+alpha PNG, because map_server's scale
    mode marks unknown cells only by transparency, which PGM cannot hold.
    """
    yaml_path, image_path = map_files(target, mode)
    yaml_path.parent.mkdir(parents=True, exist_ok=True)
    pixels = _pixels_for(grid.data, mode, occupied_thresh, free_thresh)[::-1]
    if mode == "scale":
        _replace_atomically(image_path, lambda p: Image.fromarray(np.ascontiguousarray(pixels)).save(p, "PNG"))
    else:
        _replace_atomically(image_path, lambda p: write_pgm(p, pixels))
    origin = grid.info.origin
    doc = {"image": image_path.name, "resolution": float(grid.info.resolution),
           "origin": [float(origin.x), float(origin.y), float(origin.theta)], "negate": 0,
           "occupied_thresh": float(occupied_thresh), "free_thresh": float(free_thresh), "mode": mode}
    _replace_atomically(yaml_path, lambda p: p.write_text(yaml.safe_dump(doc, sort_keys=False)))
    return yaml_path
