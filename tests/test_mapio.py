"""ROS map_server format: loading real maps, every mode, saving round trips, errors, yawed origins."""
import math

import numpy as np
import pytest
import yaml
from PIL import Image

from conftest import SHARED_DATA
from omninav.schemas.messages import MapMetaData, OccupancyGrid, Pose2D
from omninav.services.map_server.mapio import REQUIRED_KEYS, MapError, load_map, save_map
from omninav.geometry.grid import cell_to_world, in_grid, world_to_cell

MAPS = SHARED_DATA / "maps"
DEFAULTS = {"resolution": 0.1, "origin": [0.0, 0.0, 0.0], "negate": 0, "occupied_thresh": 0.65,
            "free_thresh": 0.196}


def write_map(tmp_path, image_name, **overrides):
    doc = {"image": image_name, **DEFAULTS, **overrides}
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def write_p2(path, rows, maxval=255):
    height, width = len(rows), len(rows[0])
    body = "\n".join(" ".join(str(v) for v in row) for row in rows)
    path.write_text(f"P2\n# a comment\n{width} {height}\n{maxval}\n{body}\n")


# ---------------------------------------------------------------- real maps

@pytest.mark.skipif(not (MAPS / "willow-full-0.05.yaml").exists(), reason="shared data not present")
def test_willow_loads_with_its_size_and_map_server_thresholds():
    grid = load_map(MAPS / "willow-full-0.05.yaml")
    assert (grid.info.width, grid.info.height, grid.info.resolution) == (1165, 945, 0.05)
    assert grid.data.shape == (945, 1165) and grid.data.dtype == np.int8
    raw = (MAPS / "willow-full-0.05.pgm").read_bytes()
    pixels = np.frombuffer(raw[-1165 * 945:], np.uint8).reshape(945, 1165)
    # p = (255 - v)/255: occupied if p > 0.65 (v <= 89), free if p < 0.196 (v >= 206)
    expected = np.where(pixels <= 89, 100, np.where(pixels >= 206, 0, -1))
    np.testing.assert_array_equal(grid.data, expected[::-1])  # image row 0 is the top
    assert (grid.data == 100).sum() > 1000 and (grid.data == 0).sum() > 100_000


@pytest.mark.skipif(not (MAPS / "basement_fixed.yaml").exists(), reason="shared data not present")
def test_basement_png_with_yawed_origin():
    grid = load_map(MAPS / "basement_fixed.yaml")
    info = grid.info
    assert (info.width, info.height, info.resolution) == (1300, 1300, 0.0504)
    assert (info.origin.x, info.origin.y, info.origin.theta) == (25.9, 48.5, 3.14)
    rgb = np.asarray(Image.open(MAPS / "basement_fixed.png").convert("RGB"), np.float64).mean(axis=2)
    p = (255 - rgb) / 255
    np.testing.assert_array_equal(grid.data[::-1] == 100, p > 0.65)
    np.testing.assert_array_equal(grid.data[::-1] == 0, p < 0.196)
    # yaw ≈ π: cell (0, 0) lies just below-left of the origin, and columns run towards −x
    x, y = cell_to_world(info, 0, 0)
    assert x == pytest.approx(25.9 - 0.0252, abs=1e-3) and y == pytest.approx(48.5 - 0.0252, abs=1e-3)
    x1, y1 = cell_to_world(info, 0, 100)
    assert x1 - x == pytest.approx(100 * 0.0504 * math.cos(3.14)) and y1 - y == pytest.approx(100 * 0.0504 * math.sin(3.14))
    rows, cols = np.nonzero(grid.data == 0)
    wx, wy = cell_to_world(info, rows, cols)
    assert wx.max() < 25.9 + 0.2 and wy.max() < 48.5 + 0.2  # the map lies towards −x, −y
    np.testing.assert_array_equal(world_to_cell(info, wx, wy), (rows, cols))


# ---------------------------------------------------------------- cells and the world

def test_cell_world_conversion_with_a_quarter_turn_origin():
    info = MapMetaData(resolution=0.5, width=4, height=3, origin=Pose2D(1.0, 2.0, math.pi / 2))
    # local (col + 0.5, row + 0.5)·res rotated a quarter turn: x = 1 − local_y, y = 2 + local_x
    np.testing.assert_allclose(cell_to_world(info, 0, 0), (0.75, 2.25))
    np.testing.assert_allclose(cell_to_world(info, 0, 1), (0.75, 2.75))   # columns run along +y
    np.testing.assert_allclose(cell_to_world(info, 1, 0), (0.25, 2.25))   # rows run along −x
    np.testing.assert_array_equal(world_to_cell(info, 0.26, 2.24), (1, 0))
    np.testing.assert_array_equal(world_to_cell(info, 1.1, 2.1), (-1, 0))
    assert not in_grid(info, -1, 0) and in_grid(info, 2, 3) and not in_grid(info, 3, 0)
    rng = np.random.default_rng(1)
    rows, cols = rng.integers(0, 3, 50), rng.integers(0, 4, 50)
    np.testing.assert_array_equal(world_to_cell(info, *cell_to_world(info, rows, cols)), (rows, cols))


# ---------------------------------------------------------------- modes

GREYS = [0, 89, 90, 150, 205, 206, 254, 255]


def expected_scale(grey, negate=False, occ=0.65, free=0.196):
    p = (grey if negate else 255 - grey) / 255
    return 100 if p > occ else 0 if p < free else int(1 + 98 * (p - free) / (occ - free))


@pytest.mark.parametrize("mode, negate, expected", [
    ("trinary", 0, [100, 100, -1, -1, -1, 0, 0, 0]),
    ("trinary", 1, [0, -1, -1, -1, 100, 100, 100, 100]),
    ("scale", 0, [expected_scale(g) for g in GREYS]),
    ("scale", 1, [expected_scale(g, negate=True) for g in GREYS]),
    ("raw", 0, [0, 89, 90, -1, -1, -1, -1, -1]),
    ("raw", 1, [-1, -1, -1, -1, 50, 49, 1, 0]),
])
def test_modes_follow_map_server(tmp_path, mode, negate, expected):
    write_p2(tmp_path / "m.pgm", [GREYS])
    grid = load_map(write_map(tmp_path, "m.pgm", mode=mode, negate=negate))
    assert grid.data.tolist() == [expected]
    assert 1 < expected_scale(150) < 99  # the scale case really exercises the band


def test_image_top_row_is_the_top_of_the_map(tmp_path):
    rows = [[0, 0, 0], [254, 254, 254], [254, 205, 254]]
    write_p2(tmp_path / "m.pgm", rows)
    grid = load_map(write_map(tmp_path, "m.pgm", origin=[-1.0, 3.0, 0.0]))
    assert grid.data.tolist() == [[0, -1, 0], [0, 0, 0], [100, 100, 100]]
    assert (grid.info.width, grid.info.height) == (3, 3)
    assert grid.header.frame_id == "map"


def test_p2_with_small_maxval_is_stretched(tmp_path):
    write_p2(tmp_path / "m.pgm", [[0, 15, 5]], maxval=15)
    grid = load_map(write_map(tmp_path, "m.pgm", mode="raw"))
    assert grid.data.tolist() == [[0, -1, 85]]  # 15 → 255 → unknown; 5 → 85


def test_png_alpha_marks_unknown_in_scale_mode_and_is_averaged_in_trinary(tmp_path):
    pixels = np.array([[[150, 255], [150, 0], [0, 0], [254, 255]]], np.uint8)  # grey, alpha
    Image.fromarray(pixels).save(tmp_path / "m.png")
    scale = load_map(write_map(tmp_path, "m.png", mode="scale")).data.tolist()
    assert scale == [[expected_scale(150), -1, 100, 0]]
    trinary = load_map(write_map(tmp_path, "m.png", mode="trinary")).data.tolist()
    # trinary averages alpha in, as ROS does: (150 + 0)/2 = 75 → occupied, (0 + 0)/2 → occupied
    assert trinary == [[-1, 100, 100, 0]]


def test_rgb_png_channels_are_averaged(tmp_path):
    Image.fromarray(np.array([[[255, 255, 0], [30, 30, 30]]], np.uint8)).save(tmp_path / "m.png")
    assert load_map(write_map(tmp_path, "m.png")).data.tolist() == [[-1, 100]]  # avg 170 → p 0.33


# ---------------------------------------------------------------- saving

def random_grid(values, shape=(7, 9), seed=0, origin=Pose2D(-2.5, 1.25, 0.7)):
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array(values, np.int8), size=shape)
    return OccupancyGrid(info=MapMetaData(resolution=0.0504, width=shape[1], height=shape[0], origin=origin),
                         data=data)


def test_trinary_round_trip_with_yawed_origin(tmp_path):
    grid = random_grid([-1, 0, 100])
    yaml_path = save_map(grid, tmp_path / "maps" / "room")
    assert yaml_path == tmp_path / "maps" / "room.yaml"
    assert (tmp_path / "maps" / "room.pgm").read_bytes()[:2] == b"P5"
    doc = yaml.safe_load(yaml_path.read_text())
    assert set(REQUIRED_KEYS) <= set(doc) and doc["image"] == "room.pgm" and doc["mode"] == "trinary"
    back = load_map(yaml_path)
    np.testing.assert_array_equal(back.data, grid.data)
    assert back.info == grid.info
    assert not any(p.name.startswith(".") for p in (tmp_path / "maps").iterdir())  # no temp files left


def test_trinary_save_thresholds_intermediate_values(tmp_path):
    grid = random_grid([-1, 0, 10, 50, 80, 100])
    back = load_map(save_map(grid, tmp_path / "m.yaml")).data
    expected = np.where(grid.data < 0, -1, np.where(grid.data > 65, 100, np.where(grid.data < 19.6, 0, -1)))
    np.testing.assert_array_equal(back, expected)


def test_raw_round_trip_is_exact(tmp_path):
    grid = random_grid(list(range(-1, 101)), shape=(20, 30))
    back = load_map(save_map(grid, tmp_path / "m", mode="raw"))
    np.testing.assert_array_equal(back.data, grid.data)


def test_scale_round_trip_within_one_percent(tmp_path):
    grid = random_grid(list(range(-1, 101)), shape=(20, 30))
    yaml_path = save_map(grid, tmp_path / "m", mode="scale")
    assert (tmp_path / "m.png").exists()
    back = load_map(yaml_path).data.astype(int)
    want = grid.data.astype(int)
    np.testing.assert_array_equal(back == -1, want == -1)
    np.testing.assert_array_equal(back[np.isin(want, (0, 100))], want[np.isin(want, (0, 100))])
    assert np.abs(back - want).max() <= 1


# ---------------------------------------------------------------- errors

def test_missing_yaml_file(tmp_path):
    with pytest.raises(MapError, match=r"nothere\.yaml: no such file"):
        load_map(tmp_path / "nothere.yaml")


@pytest.mark.parametrize("key", REQUIRED_KEYS)
def test_yaml_missing_a_key_names_it(tmp_path, key):
    write_p2(tmp_path / "m.pgm", [[0]])
    path = write_map(tmp_path, "m.pgm")
    doc = yaml.safe_load(path.read_text())
    del doc[key]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(MapError, match=rf"m\.yaml: missing key '{key}'"):
        load_map(path)


@pytest.mark.parametrize("key, value", [("origin", [1, 2]), ("resolution", -0.05), ("mode", "fancy"),
                                        ("negate", 2), ("occupied_thresh", 1.5), ("free_thresh", 0.9)])
def test_yaml_bad_values_name_the_key(tmp_path, key, value):
    write_p2(tmp_path / "m.pgm", [[0]])
    with pytest.raises(MapError, match=rf"m\.yaml: key '{key}'"):
        load_map(write_map(tmp_path, "m.pgm", **{key: value}))


def test_not_yaml(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("image: [unclosed\n")
    with pytest.raises(MapError, match=r"m\.yaml: not valid YAML"):
        load_map(path)


def test_missing_image(tmp_path):
    with pytest.raises(MapError, match=r"m\.yaml: image .*gone\.pgm: no such file"):
        load_map(write_map(tmp_path, "gone.pgm"))


def test_image_that_is_neither_pgm_nor_png(tmp_path):
    Image.fromarray(np.zeros((4, 4), np.uint8)).save(tmp_path / "m.bmp")
    with pytest.raises(MapError, match=r"m\.bmp: not a PGM \(P5/P2\) or PNG image"):
        load_map(write_map(tmp_path, "m.bmp"))


def test_truncated_pgm(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n10 10\n255\n" + bytes(57))
    with pytest.raises(MapError, match=r"m\.pgm: truncated: 57 of 100 pixels"):
        load_map(write_map(tmp_path, "m.pgm"))
    (tmp_path / "m.pgm").write_bytes(b"P5\n10 ")
    with pytest.raises(MapError, match=r"m\.pgm: truncated PGM header"):
        load_map(write_map(tmp_path, "m.pgm"))


def test_sixteen_bit_pgm_is_refused(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 1\n65535\n" + bytes(4))
    with pytest.raises(MapError, match=r"only 8-bit"):
        load_map(write_map(tmp_path, "m.pgm"))


def test_truncated_png(tmp_path):
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8)).save(tmp_path / "full.png")
    data = (tmp_path / "full.png").read_bytes()
    (tmp_path / "m.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(MapError, match=r"m\.png: unreadable PNG"):
        load_map(write_map(tmp_path, "m.png"))
