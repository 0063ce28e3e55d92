"""Camera files: cameras.json round trip and validation, OpenCV YAML, Qualisys .qca.txt."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.camera.triangulation import closest_point_to_lines, triangulate_views
from mocapkit.errors import FormatError
from mocapkit.io.cameras import (
    load_cameras,
    read_cameras,
    read_opencv_calibration,
    read_qualisys,
    write_cameras,
)


def _cams() -> list[Camera]:
    k = intrinsics_from_fov((1920, 1080), 60.0)
    return [
        Camera(
            "left",
            (1920, 1080),
            k,
            [-0.1, 0.02, 0.001, -0.002, 0.0003],
            look_at((2000.0, -3000.0, 1600.0), (0.0, 0.0, 1000.0)),
        ),
        Camera(
            "right",
            (1280, 720),
            k * [[0.5], [0.5], [1]],
            [],
            look_at((-2500.0, -2800.0, 1400.0), (0.0, 100.0, 900.0)),
        ),
    ]


def _doc() -> dict:  # type: ignore[type-arg]
    c = _cams()[0]
    return {
        "format": 1,
        "cameras": [
            {
                "name": c.name,
                "image_size": list(c.image_size),
                "K": c.K.tolist(),
                "dist": c.dist.tolist(),
                "camera_from_world": c.camera_from_world.tolist(),
            }
        ],
    }


def _write(tmp_path: Path, doc: object) -> Path:
    p = tmp_path / "cameras.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    return p


def test_round_trip_is_exact(tmp_path: Path) -> None:
    cams = _cams()
    path = tmp_path / "sub" / "cameras.json"
    write_cameras(path, cams)
    back = read_cameras(path)
    assert [c.name for c in back] == ["left", "right"]
    for a, b in zip(cams, back):
        assert a.image_size == b.image_size
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.dist, b.dist)
        np.testing.assert_array_equal(a.camera_from_world, b.camera_from_world)
    assert load_cameras(path)[1].name == "right"
    assert [p.name for p in path.parent.iterdir()] == ["cameras.json"]  # no temp file left


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda d: d.pop("format"), "missing key 'format'"),
        (lambda d: d.update(format=2), "format: expected version 1, found 2"),
        (lambda d: d.update(cameras=[]), "cameras: expected a non-empty list"),
        (lambda d: d["cameras"][0].pop("K"), r"cameras\[0\]: missing key\(s\) K"),
        (lambda d: d["cameras"][0].update(lens=1), r"unknown key\(s\) lens"),
        (
            lambda d: d["cameras"][0].update(K=[[1, 0, 0], [0, 1, 0]]),
            r"cameras\[0\] \('left'\)\.K: expected shape \(3, 3\), found \(2, 3\)",
        ),
        (
            lambda d: d["cameras"][0].update(image_size=[1920]),
            r"image_size: expected \[width, height\]",
        ),
        (
            lambda d: d["cameras"][0].update(dist=[0.1, 0.2, 0.3]),
            "dist: expected 0, 4, 5, 8, 12, 14 .* found 3",
        ),
        (
            lambda d: d["cameras"][0]["camera_from_world"][0].__setitem__(0, 2.0),
            "camera_from_world rotation part: expected a proper rotation",
        ),
        (
            lambda d: d["cameras"][0]["camera_from_world"][1].__setitem__(3, float("nan")),
            "camera_from_world: expected finite numbers, found NaN",
        ),
        (
            lambda d: d["cameras"].append(dict(d["cameras"][0])),
            r"duplicate camera name\(s\) 'left'",
        ),
        (lambda d: d["cameras"][0].update(name=""), r"\.name: expected a non-empty string"),
    ],
)
def test_invalid_documents_are_refused(tmp_path: Path, mutate, pattern: str) -> None:  # type: ignore[no-untyped-def]
    doc = _doc()
    mutate(doc)
    path = _write(tmp_path, doc)
    with pytest.raises(FormatError, match=pattern) as info:
        read_cameras(path)
    assert str(path) in str(info.value)


def test_malformed_json_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "cameras.json"
    bad.write_text('{"format": 1, "cameras": [', encoding="utf-8")
    with pytest.raises(FormatError, match=r"cameras\.json: not valid JSON \(line 1"):
        read_cameras(bad)
    with pytest.raises(FormatError, match="camera file not found"):
        read_cameras(tmp_path / "nope.json")
    with pytest.raises(FormatError, match="unknown camera file type"):
        load_cameras(tmp_path / "cams.txt")


def test_write_refuses_duplicates_and_empty(tmp_path: Path) -> None:
    c = _cams()[0]
    with pytest.raises(FormatError, match=r"duplicate camera name\(s\) 'left'"):
        write_cameras(tmp_path / "c.json", [c, c])
    with pytest.raises(FormatError, match="at least one camera"):
        write_cameras(tmp_path / "c.json", [])
    assert not (tmp_path / "c.json").exists()


def test_opencv_yaml_calibration(shared_data: Path) -> None:
    cam = read_opencv_calibration(shared_data / "calib/stereo_chessboard/left_intrinsics.yml")
    assert cam.name == "left_intrinsics"
    assert cam.image_size == (640, 480)
    np.testing.assert_allclose(
        cam.K[[0, 1, 0, 1], [0, 1, 2, 2]],
        [535.91573396163199, 535.91573396163199, 342.28315473308373, 235.57082909788173],
    )
    assert cam.dist.shape == (5,) and cam.dist[0] == pytest.approx(-0.26637260909660682)
    np.testing.assert_array_equal(cam.camera_from_world, np.eye(4))


def test_opencv_yaml_with_extrinsics_and_errors(tmp_path: Path) -> None:
    p = tmp_path / "cam.yml"
    p.write_text(
        "%YAML:1.0\n---\nimage_width: 800\nimage_height: 600\n"
        "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 700., 0., 400., 0., 700., 300., 0., 0., 1. ]\n"
        "R: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n"
        "   data: [ 0., 0., 1.5707963267948966 ]\n"
        "T: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ 0.1, 0.2, 3. ]\n",
        encoding="utf-8",
    )
    cam = read_opencv_calibration(p, name="cam", translation_mm_per_unit=1000.0)
    np.testing.assert_allclose(cam.camera_from_world[:3, 3], [100.0, 200.0, 3000.0])
    np.testing.assert_allclose(
        cam.camera_from_world[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12
    )
    assert cam.dist.shape == (0,)
    q = tmp_path / "nok.yml"
    q.write_text("%YAML:1.0\n---\nimage_width: 800\nimage_height: 600\n", encoding="utf-8")
    with pytest.raises(
        FormatError,
        match=r"nok\.yml: missing camera matrix; expected one of the keys camera_matrix",
    ):
        read_opencv_calibration(q)


QCA_RELATIVE = "video/pose2sim_demo_singleperson/calibration/Calib.qca.txt"


def test_qualisys_units_and_orientation(shared_data: Path) -> None:
    cams = read_qualisys(shared_data / QCA_RELATIVE)
    assert [c.name for c in cams] == ["cam01", "cam02", "cam03", "cam04"]
    c1 = cams[0]
    assert c1.image_size == (1088, 1920)  # portrait video window 0..1087 x 0..1919
    # Sub-pixel factor 64 = sensorMaxU 69568 / 1087 px.
    np.testing.assert_allclose(
        c1.K,
        [
            [107599.671875 / 64, 0, 34110.316406 / 64],
            [0, 107588.828125 / 64, 60680.792969 / 64],
            [0, 0, 1],
        ],
    )
    np.testing.assert_allclose(c1.dist, [-0.046183, 0.139983, 0.000608, 0.00069, 0.0])
    np.testing.assert_allclose(
        c1.center_in_world, [1460.2323709212087, -1909.1590482454608, 1896.5058524092062], atol=1e-9
    )
    for c in cams:
        # World +Z (up) appears upwards in every portrait image, cameras ~1.7-2.1 m high.
        base = c.project([[-900.0, 0.0, 0.0], [-900.0, 0.0, 1500.0]])
        assert base[1, 1] < base[0, 1] - 500
        assert 1500 < c.center_in_world[2] < 2200


def test_qualisys_views_agree(shared_data: Path) -> None:
    cams = read_qualisys(shared_data / QCA_RELATIVE)
    # The least-squares meeting point of the four optical axes must be in front of every
    # camera and project inside every image; with the opposite rotation convention it
    # lands ~8 m away, below the floor, behind the cameras.
    axes = np.stack([c.world_from_camera[:3, 2] for c in cams])
    centres = np.stack([c.center_in_world for c in cams])
    meet = closest_point_to_lines(centres, axes)
    for c in cams:
        assert c.to_camera(meet)[2] > 1000.0
        px = c.project(meet)
        assert c.in_image(px, margin_px=100), (c.name, px)
    # A point near camera 1's image centre, 3.3 m along its axis, is seen by the other three,
    # and triangulating its four projections gives it back.
    point = centres[0] + 3300.0 * axes[0]
    px = np.stack([c.project(point) for c in cams])
    assert all(c.in_image(p) for c, p in zip(cams, px))
    np.testing.assert_allclose(triangulate_views(cams, px[:, None])[0], point, atol=1e-6)
    assert load_cameras(shared_data / QCA_RELATIVE)[3].name == "cam04"


def test_qualisys_malformed(tmp_path: Path) -> None:
    p = tmp_path / "bad.qca.txt"
    p.write_text(
        "<calibration><cameras><camera serial='c1'><transform x='1'/></camera></cameras>"
        "</calibration>",
        encoding="utf-8",
    )
    with pytest.raises(
        FormatError,
        match=r"bad\.qca\.txt: camera 0 \(serial 'c1'\) <transform>: missing attribute 'r11'",
    ):
        read_qualisys(p)
    p.write_text("<calibration><cameras>", encoding="utf-8")
    with pytest.raises(FormatError, match="not valid XML"):
        read_qualisys(p)
