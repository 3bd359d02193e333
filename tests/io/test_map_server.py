"""map_server maps: trinary writing, orientation, ROS interpretation of images in every mode."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from doorbatch.errors import InputDataError
from doorbatch.io.map_server import decode_pgm, encode_pgm, read_map, write_map
from doorbatch.maps import OccupancyMap


def write_yaml(path: Path, image: str, **fields: object) -> Path:
    content = {"image": image, "resolution": 0.1, "origin": [1.0, 2.0, 0.0], "negate": 0,
               "occupied_thresh": 0.65, "free_thresh": 0.196, **fields}
    path.write_text(yaml.safe_dump(content))
    return path


def map_of_pixels(tmp_path: Path, pixels: np.ndarray, **fields: object) -> OccupancyMap:
    """Read a one-row (or any) grayscale image through a YAML with the given fields."""
    (tmp_path / "m.pgm").write_bytes(encode_pgm(pixels.astype(np.uint8)))
    return read_map(write_yaml(tmp_path / "m.yaml", "m.pgm", **fields))


# ------------------------------------------------------------------------------------ OccupancyMap


def test_cell_world_round_trip_with_rotated_origin() -> None:
    grid = OccupancyMap(np.zeros((40, 30), np.int8), 0.05, -1.0, 3.0, 0.7)
    rng = np.random.default_rng(0)
    ij = rng.integers(0, 30, size=(100, 2))
    assert np.array_equal(grid.world_to_cell(grid.cell_to_world(ij)), ij)
    assert grid.width == 30 and grid.height == 40


def test_cell_zero_and_axes_without_rotation() -> None:
    grid = OccupancyMap(np.zeros((10, 20), np.int8), 0.5, 1.0, 2.0)
    assert np.allclose(grid.cell_to_world([0, 0]), [1.25, 2.25])
    assert np.allclose(grid.cell_to_world([3, 0]), [1.25, 3.75])  # rows go along y
    assert grid.world_to_cell([[1.01, 2.01], [10.9, 2.1], [0.9, 2.1]]).tolist() == [[0, 0], [0, 19], [0, -1]]
    assert grid.contains(grid.world_to_cell([[1.01, 2.01], [0.9, 2.1]])).tolist() == [True, False]


@pytest.mark.parametrize(
    ("occupancy", "resolution"),
    [(np.zeros((2, 2), np.int16), 0.1), (np.full((2, 2), 101, np.int8), 0.1), (np.zeros((2, 2), np.int8), 0.0),
     (np.zeros(4, np.int8), 0.1)],
)
def test_invalid_maps_are_rejected(occupancy: np.ndarray, resolution: float) -> None:
    with pytest.raises(ValueError):
        OccupancyMap(occupancy, resolution)


# ----------------------------------------------------------------------------------------- writing


def test_written_yaml_has_the_contract_fields(tmp_path: Path) -> None:
    grid = OccupancyMap(np.zeros((3, 4), np.int8), 0.05, -12.5, 3.25, 0.1)
    write_map(grid, tmp_path / "map.yaml")
    fields = yaml.safe_load((tmp_path / "map.yaml").read_text())
    assert fields == {"image": "map.pgm", "resolution": 0.05, "origin": [-12.5, 3.25, 0.1], "negate": 0,
                      "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pgm", "map.yaml"]


def test_pgm_is_binary_p5_and_high_y_is_the_top_row(tmp_path: Path) -> None:
    occupancy = np.zeros((5, 3), np.int8)
    occupancy[4, 2] = 100  # highest y, highest x
    occupancy[0, 0] = -1  # lowest y, lowest x
    write_map(OccupancyMap(occupancy, 0.1), tmp_path / "map.yaml")
    data = (tmp_path / "map.pgm").read_bytes()
    assert data.startswith(b"P5\n")
    image = decode_pgm(data, tmp_path / "map.pgm")
    assert image.shape == (5, 3)
    assert image[0, 2] == 0  # occupied, top row
    assert image[4, 0] == 205  # unknown, bottom row
    assert np.count_nonzero(image == 254) == 13
    opencv_image = cv2.imread(str(tmp_path / "map.pgm"), cv2.IMREAD_UNCHANGED)
    assert opencv_image is not None and np.array_equal(opencv_image, image)


def test_trinary_write_thresholds(tmp_path: Path) -> None:
    values = np.array([[-1, 0, 19, 20, 50, 64, 65, 100]], np.int8)
    write_map(OccupancyMap(values, 0.1), tmp_path / "map.yaml")
    image = decode_pgm((tmp_path / "map.pgm").read_bytes(), tmp_path / "map.pgm")
    assert image[0].tolist() == [205, 254, 254, 205, 205, 205, 0, 0]
    assert read_map(tmp_path / "map.yaml").occupancy[0].tolist() == [-1, 0, 0, -1, -1, -1, 100, 100]


def test_write_rejects_thresholds_that_would_not_read_back(tmp_path: Path) -> None:
    grid = OccupancyMap(np.zeros((1, 1), np.int8), 0.1)
    with pytest.raises(ValueError, match="free_thresh"):
        write_map(grid, tmp_path / "map.yaml", free_thresh=0.3)
    assert list(tmp_path.iterdir()) == []


trinary_grids = hnp.arrays(np.int8, hnp.array_shapes(min_dims=2, max_dims=2, max_side=12),
                           elements=st.sampled_from([-1, 0, 100]))
finite = st.floats(-1e4, 1e4, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(occupancy=trinary_grids, resolution=st.floats(1e-4, 10.0), x=finite, y=finite,
       yaw=st.floats(-3.14, 3.14))
def test_trinary_map_round_trip(tmp_path_factory: pytest.TempPathFactory, occupancy: np.ndarray,
                                resolution: float, x: float, y: float, yaw: float) -> None:
    path = tmp_path_factory.mktemp("rt") / "map.yaml"
    write_map(OccupancyMap(occupancy, resolution, x, y, yaw), path)
    back = read_map(path)
    assert np.array_equal(back.occupancy, occupancy)
    assert (back.resolution_m, back.origin_x_m, back.origin_y_m, back.origin_yaw_rad) == (resolution, x, y, yaw)


# ----------------------------------------------------------------------------------------- reading


def test_trinary_read_thresholds_on_constructed_image(tmp_path: Path) -> None:
    # p = (255 - v) / 255: occupied if p > 0.65 (v <= 89), free if p < 0.196 (v >= 206)
    pixels = np.array([[0, 89, 90, 128, 205, 206, 254, 255]])
    grid = map_of_pixels(tmp_path, pixels)
    assert grid.occupancy[0].tolist() == [100, 100, -1, -1, -1, 0, 0, 0]
    assert (grid.resolution_m, grid.origin_x_m, grid.origin_y_m) == (0.1, 1.0, 2.0)


def test_negate_swaps_black_and_white(tmp_path: Path) -> None:
    pixels = np.array([[0, 49, 128, 166, 255]])
    grid = map_of_pixels(tmp_path, pixels, negate=1)
    assert grid.occupancy[0].tolist() == [0, 0, -1, 100, 100]


def test_scale_mode_interpolates_between_thresholds(tmp_path: Path) -> None:
    values = np.arange(256)
    grid = map_of_pixels(tmp_path, values[None, :], mode="scale")
    p = (255 - values) / 255
    between = (p <= 0.65) & (p >= 0.196)
    expected = np.where(p > 0.65, 100, 0)
    expected[between] = np.trunc(1 + 98 * (p[between] - 0.196) / (0.65 - 0.196))
    assert np.array_equal(grid.occupancy[0], expected)
    assert grid.occupancy[0, 150] == 47
    assert set(grid.occupancy[0, between].tolist()) <= set(range(1, 100))
    assert np.all(np.diff(grid.occupancy[0].astype(int)) <= 0)  # brighter is never more occupied


def test_raw_mode_keeps_values_up_to_100(tmp_path: Path) -> None:
    grid = map_of_pixels(tmp_path, np.array([[0, 37, 100, 101, 205, 255]]), mode="raw")
    assert grid.occupancy[0].tolist() == [0, 37, 100, -1, -1, -1]


def test_ascii_p2_with_comments_and_small_maxval(tmp_path: Path) -> None:
    (tmp_path / "a.pgm").write_text("P2\n# made by hand\n3 2\n# max\n15\n0 15 8\n15 15 0\n")
    grid = read_map(write_yaml(tmp_path / "a.yaml", "a.pgm"))
    # image top row [0, 255, 136] is the map's highest row
    assert grid.occupancy.tolist() == [[0, 0, 100], [100, 0, -1]]


def test_png_and_color_png_via_opencv(tmp_path: Path) -> None:
    gray = np.array([[0, 128, 255], [255, 0, 128]], np.uint8)
    cv2.imwrite(str(tmp_path / "g.png"), gray)
    from_png = read_map(write_yaml(tmp_path / "g.yaml", "g.png"))
    from_pgm = map_of_pixels(tmp_path, gray)
    assert np.array_equal(from_png.occupancy, from_pgm.occupancy)
    color = np.stack([gray, gray, gray], axis=2)
    cv2.imwrite(str(tmp_path / "c.png"), color)
    assert np.array_equal(read_map(write_yaml(tmp_path / "c.yaml", "c.png")).occupancy, from_pgm.occupancy)


def test_transparent_pixels_are_unknown_in_scale_mode(tmp_path: Path) -> None:
    bgra = np.zeros((1, 3, 4), np.uint8)
    bgra[0, :, :3] = 150  # in between the thresholds
    bgra[0, :, 3] = [255, 0, 255]
    cv2.imwrite(str(tmp_path / "t.png"), bgra)
    grid = read_map(write_yaml(tmp_path / "t.yaml", "t.png", mode="scale"))
    assert grid.occupancy[0].tolist() == [47, -1, 47]


def test_image_path_is_relative_to_the_yaml(tmp_path: Path) -> None:
    (tmp_path / "maps" / "img").mkdir(parents=True)
    (tmp_path / "maps" / "img" / "m.pgm").write_bytes(encode_pgm(np.zeros((2, 2), np.uint8)))
    yaml_path = write_yaml(tmp_path / "maps" / "m.yaml", "img/m.pgm")
    assert read_map(yaml_path).occupancy.tolist() == [[100, 100], [100, 100]]


def test_yaml_numbers_written_like_1e_minus_5_are_accepted(tmp_path: Path) -> None:
    (tmp_path / "m.pgm").write_bytes(encode_pgm(np.zeros((1, 1), np.uint8)))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 1e-05\norigin: [0, 0, 0]\nnegate: 0\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert read_map(tmp_path / "m.yaml").resolution_m == 1e-05


@pytest.mark.parametrize(
    ("yaml_text", "image_bytes", "bad_file", "message"),
    [
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0]\n", None, "m.yaml", "origin"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", None, "m.yaml", "positive"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: fancy\n", None, "m.yaml", "mode"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 2\n", None, "m.yaml", "negate"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.1\nfree_thresh: 0.6\n", None,
         "m.yaml", "swapped"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: scale\noccupied_thresh: 0.5\nfree_thresh: 0.5\n",
         None, "m.yaml", "scale mode"),
        ("origin: [0, 0, 0]\nresolution: 0.1\n", None, "m.yaml", "image"),
        ("image: [unclosed\n", None, "m.yaml", "not valid YAML"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"", "m.pgm", "cannot read"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"P5\n4 4\n255\n\x00\x00", "m.pgm", "truncated"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"P5\n4 4\n65536\n", "m.pgm", "1..65535"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"P5\n4 4\n65535\n" + bytes(30), "m.pgm",
         "truncated: 15 of 16"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"P2\n2 1\n255\n1 300\n", "m.pgm", "outside"),
        ("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", b"garbage bytes", "m.pgm", "decode"),
    ],
)
def test_bad_files_raise_input_data_error_naming_the_file(
    tmp_path: Path, yaml_text: str, image_bytes: bytes | None, bad_file: str, message: str
) -> None:
    (tmp_path / "m.yaml").write_text(yaml_text)
    if image_bytes:
        (tmp_path / "m.pgm").write_bytes(image_bytes)
    with pytest.raises(InputDataError, match=message) as info:
        read_map(tmp_path / "m.yaml")
    assert info.value.path == str(tmp_path / bad_file)


def test_missing_yaml_names_it(tmp_path: Path) -> None:
    with pytest.raises(InputDataError) as info:
        read_map(tmp_path / "nothing.yaml")
    assert info.value.path == str(tmp_path / "nothing.yaml")


def test_16_bit_images_read_as_their_8_bit_shades(tmp_path: Path) -> None:
    """A 16-bit PGM (two bytes per sample, most significant first) and a 16-bit PNG scale by their maximum, as
    GraphicsMagick (Nav2's map_server) does: the same map as the 8-bit image of the same shades."""
    shades = np.array([[0, 254, 205], [254, 0, 254]], dtype=np.uint8)
    wide = (shades.astype(np.uint16) * 257).astype(">u2")  # 8-bit v is 16-bit 257·v
    (tmp_path / "m8.pgm").write_bytes(encode_pgm(shades))
    (tmp_path / "m16.pgm").write_bytes(b"P5\n3 2\n65535\n" + wide.tobytes())
    assert cv2.imwrite(str(tmp_path / "m16.png"), wide.astype(np.uint16))
    maps = []
    for name in ("m8.pgm", "m16.pgm", "m16.png"):
        (tmp_path / f"{name}.yaml").write_text(f"image: {name}\nresolution: 0.1\norigin: [0, 0, 0]\n")
        maps.append(read_map(tmp_path / f"{name}.yaml").occupancy)
    assert maps[0].tolist() == [[0, 100, 0], [100, 0, -1]]  # flipped: the image's top row is the map's last
    assert all(np.array_equal(m, maps[0]) for m in maps[1:])


def test_trinary_mode_averages_alpha_in_as_both_map_servers_do(tmp_path: Path) -> None:
    """image_loader.cpp / Nav2 map_io: in trinary mode the alpha channel is averaged in with the colors ("to
    preserve existing behavior"): an opaque grey 205 is (3·205 + 255)/4 = 217.5, p = 0.147 < free_thresh, free; in
    scale mode alpha is left out: 205 is p = 0.196, just above free_thresh, ROS 1's 1 + 98·ratio = 1."""
    rgba = np.zeros((1, 2, 4), dtype=np.uint8)
    rgba[0, 0] = (205, 205, 205, 255)  # opaque grey
    rgba[0, 1] = (0, 0, 0, 255)  # opaque black: (0·3 + 255)/4 = 63.75, p = 0.75, occupied
    assert cv2.imwrite(str(tmp_path / "m.png"), rgba)
    for mode, expected in (("trinary", [0, 100]), ("scale", [1, 100])):
        (tmp_path / f"{mode}.yaml").write_text(f"image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nmode: {mode}\n")
        assert read_map(tmp_path / f"{mode}.yaml").occupancy[0].tolist() == expected


def test_equal_thresholds_read_a_binary_image_in_trinary_mode(tmp_path: Path) -> None:
    """free_thresh = occupied_thresh = 0.5 (a binary image, as map_server loads it): dark cells occupied, light
    free; only scale mode, which divides by their difference, refuses them."""
    (tmp_path / "m.pgm").write_bytes(encode_pgm(np.array([[0, 254]], dtype=np.uint8)))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.5\n"
                                     "free_thresh: 0.5\n")
    assert read_map(tmp_path / "m.yaml").occupancy.tolist() == [[100, 0]]

