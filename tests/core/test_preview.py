"""Preview pictures: PNG output, color bar, robust limits, NaN points, cameras, occlusion,
subsampling, errors, and ``curvature estimate --preview``."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

import curvature
from curvature import synthetic
from curvature.cli import main
from curvature.preview import (
    COLORBAR_BOX,
    NAN_COLOR,
    PLOT_BOX,
    camera,
    color_limits,
    rasterize,
    render_preview,
    subsample,
)


def decode(png: bytes) -> np.ndarray:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def box_pixels(image: np.ndarray, box) -> np.ndarray:
    """The pixels inside a figure-fraction box (left, bottom, width, height)."""
    h, w = image.shape[:2]
    left, bottom, width, height = box
    return image[int(h * (1 - bottom - height)):int(h * (1 - bottom)),
                 int(w * left):int(w * (left + width))]


@pytest.fixture(scope="module")
def torus_result():
    cloud = synthetic.torus(4000, major=2.0, minor=0.7, seed=3)
    return curvature.estimate(cloud.points, "knn", fit="monge", k=16)


@pytest.mark.parametrize("field", ["mean", "gaussian", "k1", "k2"])
def test_every_field_renders_with_a_color_bar(torus_result, field):
    image = decode(render_preview(torus_result, field))
    assert image.shape == (600, 800, 3)
    plot = box_pixels(image, PLOT_BOX)
    assert len(np.unique(plot.reshape(-1, 3), axis=0)) > 50  # a colored cloud, not blank
    # The color bar: a vertical gradient whose ends are the color map's ends.
    bar = box_pixels(image, COLORBAR_BOX)
    column = bar[:, bar.shape[1] // 2].astype(int)
    inside = column[(column.sum(axis=1) < 3 * 250)]  # skip white margins around the bar
    assert len(np.unique(inside, axis=0)) > 30
    top, bottom = inside[len(inside) // 10], inside[-len(inside) // 10]
    assert np.abs(top - bottom).sum() > 150


def test_diverging_bar_is_red_on_top_and_blue_below(torus_result):
    bar = box_pixels(decode(render_preview(torus_result, "mean")), COLORBAR_BOX)
    column = bar[:, bar.shape[1] // 2].astype(int)
    inside = column[(column.sum(axis=1) < 3 * 250)]
    top, bottom = inside[len(inside) // 10], inside[-len(inside) // 10]
    assert top[0] > top[2] + 60  # red: positive curvature (convex)
    assert bottom[2] > bottom[0] + 60  # blue: negative


@pytest.mark.parametrize("view", ["iso", "front", "side", "top"])
def test_every_view_renders(torus_result, view):
    image = decode(render_preview(torus_result, "mean", view=view, width=400, height=300))
    assert image.shape == (300, 400, 3)


def test_cameras_are_orthonormal_and_face_the_expected_way():
    for view in ("iso", "front", "side", "top"):
        rot = camera(view)
        assert np.allclose(rot @ rot.T, np.eye(3))
        assert np.isclose(np.linalg.det(rot), 1.0)  # right-handed: no mirrored pictures
    assert np.allclose(camera("front"), [[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    assert np.allclose(camera("top"), [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert np.allclose(camera("side"), [[0, 1, 0], [0, 0, 1], [1, 0, 0]])


def test_rasterize_places_points_and_keeps_the_nearest():
    red, blue, green = (1, 0, 0, 1), (0, 0, 1, 1), (0, 1, 0, 1)
    # Screen coordinates (right, up, depth): two points on top of each other, one far right.
    screen = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [10.0, 10.0, 0.0]])
    rgba = np.array([blue, red, green], dtype=float)
    image = rasterize(screen, rgba, 100, 100, margin=4)
    assert np.allclose(image[95, 4], red)  # the nearer of the two at (0, 0): bottom left
    assert not np.any(np.all(np.isclose(image, blue), axis=-1))  # the hidden one never shows
    assert np.allclose(image[4, 95], green)  # up and right: top right corner
    assert np.allclose(image[50, 50], (1, 1, 1, 1))  # background between


def test_front_plane_hides_the_back_plane():
    g = np.linspace(-1, 1, 60)
    x, z = (a.ravel() for a in np.meshgrid(g, g))
    front = np.column_stack([x, np.full_like(x, -1.0), z])  # nearer a camera at -y
    back = np.column_stack([x, np.full_like(x, 1.0), z])
    data = {"points": np.vstack([front, back]),
            "mean": np.concatenate([np.ones(len(x)), -np.ones(len(x))])}
    plot = box_pixels(decode(render_preview(data, "mean", view="front")), PLOT_BOX).astype(int)
    colored = plot[plot.sum(axis=-1) < 3 * 240]
    reds = np.sum(colored[:, 0] > colored[:, 2] + 60)
    blues = np.sum(colored[:, 2] > colored[:, 0] + 60)
    assert reds > 10000 and blues == 0


def test_robust_limits_ignore_outliers_and_nan():
    values = np.concatenate([np.linspace(-1, 2, 1000), [1e9, -1e9, np.nan, np.nan]])
    lo, hi, diverging = color_limits(values, "mean")
    assert diverging and lo == -hi and 1.8 < hi < 2.0
    lo, hi, diverging = color_limits(np.linspace(0.5, 1.5, 1000), "k1")
    assert not diverging and 0.5 < lo < 0.53 and 1.47 < hi < 1.5
    lo, hi, diverging = color_limits(np.linspace(-0.5, 1.5, 1000), "k2")  # both signs
    assert diverging and lo == -hi
    assert color_limits(np.full(10, np.nan), "gaussian") == (-1.0, 1.0, True)
    lo, hi, _ = color_limits(np.full(10, 0.25), "k1")  # constant: still a valid range
    assert lo < 0.25 < hi


def test_nan_points_are_grey(torus_result):
    data = {"points": torus_result.points, "mean": torus_result.mean.copy()}
    data["mean"][::2] = np.nan
    plot = box_pixels(decode(render_preview(data, "mean", view="top")), PLOT_BOX).astype(int)
    grey = np.all(np.abs(plot - np.round(np.array(NAN_COLOR[:3]) * 255)) <= 1, axis=-1)
    assert grey.sum() > 5000
    everything_nan = {"points": torus_result.points, "mean": np.full(len(data["mean"]), np.nan)}
    plot = box_pixels(decode(render_preview(everything_nan, "mean")), PLOT_BOX).astype(int)
    nonwhite = plot[plot.sum(axis=-1) < 3 * 250]
    assert len(nonwhite) > 0
    assert np.all(np.abs(nonwhite - np.round(np.array(NAN_COLOR[:3]) * 255)) <= 1)


def test_subsample_is_deterministic_and_bounded(torus_result):
    idx = subsample(10_000, 1000, seed=0)
    assert idx.shape == (1000,) and np.all(np.diff(idx) > 0)
    assert np.array_equal(idx, subsample(10_000, 1000, seed=0))
    assert subsample(500, 1000) is None
    first = render_preview(torus_result, "k1", max_points=1000)
    assert first == render_preview(torus_result, "k1", max_points=1000)
    assert first != render_preview(torus_result, "k1")


def test_path_output_matches_bytes(torus_result, tmp_path):
    target = tmp_path / "p.png"
    assert render_preview(torus_result, "k2", path=target) == target
    assert target.read_bytes() == render_preview(torus_result, "k2")


@pytest.mark.parametrize("kwargs, message", [
    ({"field": "curvedness"}, "field must be one of"),
    ({"view": "back"}, "view must be one of"),
    ({"width": 100}, "at least 200 x 150"),
    ({"max_points": 0}, "max_points must be >= 1"),
])
def test_bad_arguments_are_parameter_errors(torus_result, kwargs, message):
    with pytest.raises(curvature.ParameterError, match=message):
        render_preview(torus_result, **kwargs)


def test_bad_arrays_are_input_errors():
    with pytest.raises(curvature.CurvatureInputError, match="no mean"):
        render_preview({"points": np.zeros((5, 3))}, "mean")
    with pytest.raises(curvature.CurvatureInputError, match=r"expected shape \(5,\)"):
        render_preview({"points": np.zeros((5, 3)), "mean": np.zeros(4)}, "mean")
    with pytest.raises(curvature.CurvatureInputError):
        render_preview({"points": np.full((5, 3), np.nan), "mean": np.zeros(5)}, "mean")


def test_cli_estimate_writes_a_preview(tmp_path, capsys):
    source = tmp_path / "sphere.xyz"
    np.savetxt(source, synthetic.sphere(2000, radius=2.0, seed=1).points)
    out, png = tmp_path / "res.ply", tmp_path / "res.png"
    assert main(["estimate", str(source), "-o", str(out), "--method", "knn", "--fit", "monge",
                 "--k", "16", "--preview", str(png), "--preview-field", "gaussian",
                 "--preview-view", "top"]) == 0
    assert "preview     " in capsys.readouterr().err
    assert decode(png.read_bytes()).shape == (600, 800, 3)
    assert len(curvature.read(out)) == 2000


def test_cli_preview_options_are_checked(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["estimate", "x.ply", "-o", "y.ply", "--preview", "p.png", "--preview-field", "H"])
    assert "invalid choice" in capsys.readouterr().err


# -- the up axis -------------------------------------------------------------------------------

def test_z_up_cameras_are_the_presets_and_every_up_gives_a_right_handed_frame():
    from curvature.preview import UP_CHOICES, up_vector, world_frame

    for view in ("iso", "front", "side", "top"):
        assert np.allclose(camera(view, (0.0, 0.0, 1.0)), camera(view))
    for up in UP_CHOICES[1:]:
        u = up_vector(up)
        frame = world_frame(u)
        assert np.allclose(frame @ frame.T, np.eye(3)) and np.isclose(np.linalg.det(frame), 1)
        assert np.allclose(frame[2], u)
        for view in ("iso", "front", "side", "top"):
            rot = camera(view, u)
            assert np.allclose(rot @ rot.T, np.eye(3))
            if view != "top":
                assert rot[1] @ u > 0  # the world's up is up on the screen
        assert np.allclose(camera("top", u)[2], u)  # top looks down the up axis
    # y up (OpenGL, Stanford bunny): front looks from +z; -y up (a scanner's camera frame,
    # x right, y down, z forward): front looks from behind the scanner, along +z.
    assert np.allclose(camera("front", up_vector("y"))[2], [0, 0, 1])
    assert np.allclose(camera("front", up_vector("-y")), [[1, 0, 0], [0, -1, 0], [0, 0, -1]])


def test_auto_up_of_flat_and_standing_clouds():
    from curvature.preview import auto_up

    rng = np.random.default_rng(4)
    # A table top 1 below a scanner at the origin, tilted: up is its normal, towards the
    # scanner (the origin), whichever way the normal's sign came out of the eigensolver.
    normal = np.array([0.0, -0.96, -0.28])
    a = np.cross(normal, [1.0, 0.0, 0.0])
    b = np.cross(normal, a)
    table = rng.uniform(-1, 1, (5000, 1)) * a + rng.uniform(-1, 1, (5000, 1)) * b
    for offset in (-normal, normal):
        up = auto_up(table + offset * 1.5)
        assert np.allclose(up, normal if offset @ normal < 0 else -normal, atol=1e-3)
    # An object standing on the ground at y = 0 (y up), and the same at z = 0.
    blob = rng.normal(size=(3000, 3)) * [0.3, 0.2, 0.25]
    assert np.allclose(auto_up(blob + [0.0, 1.0, 0.0]), [0, 1, 0])
    assert np.allclose(auto_up(blob + [0.0, 0.0, -1.0]), [0, 0, -1])
    assert np.allclose(auto_up(blob), [0, 0, 1])  # centred: z


def test_auto_up_of_the_real_scans(shared_data):
    from curvature.preview import auto_up

    bunny = curvature.read(shared_data / "bun_zipper.ply").points
    assert np.allclose(auto_up(bunny), [0, 1, 0])  # the bunny stands on y = 0.033
    assert np.allclose(auto_up(curvature.read(shared_data / "bun000.ply").points), [0, 1, 0])
    for name in ("table_scene_mug_stereo_textured.pcd", "milk_cartoon_all_small_clorox.pcd"):
        points = curvature.read(shared_data / name).points
        up = auto_up(points[np.isfinite(points).all(axis=1)])
        assert up @ [0, -1, 0] > 0.8, (name, up)  # the table's normal, towards the sensor


def test_up_changes_the_picture_and_its_title(torus_result):
    pictures = {up: box_pixels(decode(render_preview(torus_result, "mean", up=up)), PLOT_BOX)
                for up in ("auto", "z", "x")}
    assert np.array_equal(pictures["auto"], pictures["z"])  # a centred torus: z
    assert not np.array_equal(pictures["x"], pictures["z"])
    vector = render_preview(torus_result, "mean", up=(2.0, 0.0, 0.0))
    assert np.array_equal(box_pixels(decode(vector), PLOT_BOX), pictures["x"])


@pytest.mark.parametrize("up, message", [("w", "up must be one of"), ("--x", "up must be"),
                                         ((0.0, 0.0, 0.0), "non-zero"),
                                         ((1.0, np.nan, 0.0), "non-zero finite")])
def test_bad_up_is_a_parameter_error(torus_result, up, message):
    with pytest.raises(curvature.ParameterError, match=message):
        render_preview(torus_result, up=up)


def test_color_bar_label_carries_the_unit_and_the_ticks_power_of_ten():
    from curvature.preview import bar_label, tick_exponent

    assert bar_label("mean") == "mean curvature H [1/length unit]"
    assert bar_label("gaussian") == "Gaussian curvature K [1/length unit²]"
    assert bar_label("gaussian", 3) == "Gaussian curvature K [10^3 1/length unit²]"
    assert [tick_exponent(m) for m in (0.5, 0.01, 9999.0, 12000.0, 0.004, 2e-7, 0.0)] == \
        [0, 0, 0, 3, -3, -9, 0]
    assert curvature.describe_field("k1_std").unit == "1/length unit"
    assert curvature.describe_field("k1_std").scale == "sequential"
    assert curvature.describe_field("intensity").scale == "auto"


def test_large_curvature_ticks_are_scaled_not_offset():
    # K of a 0.5 mm sphere in metres is 4e6: ticks read about 4 with 10^6 in the label.
    sphere = synthetic.sphere(2000, radius=5e-4, seed=1)
    res = curvature.estimate(sphere.points, "knn", fit="monge", k=16)
    png = render_preview(res, "gaussian")
    assert decode(png).shape == (600, 800, 3)
    from curvature.preview import color_limits, tick_exponent
    vmin, vmax, _ = color_limits(res.gaussian, "gaussian")
    assert tick_exponent(max(abs(vmin), abs(vmax))) == 6
