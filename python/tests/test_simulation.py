"""avp.Scene, avp.Camera, avp.Arm: scenes rendered to numpy as `avp render` renders them, the
arm's kinematics, and bad arrays refused by name."""

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest

import avp
from conftest import SCENARIO, run_cli


@pytest.fixture(scope="module")
def scene():
    return avp.Scene(SCENARIO, seed=2)


@pytest.fixture(scope="module")
def arm():
    return avp.Arm.load()


def test_scenarios_and_scenes():
    names = [s["name"] for s in avp.scenarios()]
    assert SCENARIO in names and avp.DEFAULT_SCENARIO in names
    # The learned gain's training family is there, marked as such (never an evaluation scene).
    training = [s["name"] for s in avp.scenarios() if s["training_only"]]
    assert training == ["generic-training"]
    a, b = avp.Scene(SCENARIO, seed=2), avp.Scene(SCENARIO, seed=2)
    fa, fb = a.fruits(), b.fruits()
    assert len(fa["instance"]) > 0
    for k in fa:
        np.testing.assert_array_equal(fa[k], fb[k])
    other = avp.Scene(SCENARIO, seed=3).fruits()
    assert not np.array_equal(fa["x"], other["x"])
    bounds = a.plant_bounds
    assert bounds.shape == (2, 3)
    inside = (fa["x"] >= bounds[0, 0]) & (fa["x"] <= bounds[1, 0])
    assert inside.all()
    assert avp.Scene().name == avp.DEFAULT_SCENARIO


@pytest.fixture(scope="module")
def cli_render(avp_binary, tmp_root, scene):
    """`avp render` of the scene at its start joints (given in degrees, as the CLI takes them)."""
    out = tmp_root / "cli-render"
    degrees = ",".join(repr(float(v)) for v in np.degrees(scene.start_joints))
    run_cli(avp_binary, "render", "--scenario", SCENARIO, "--seed", 2, "--joints", degrees,
            "--out", out)
    return out


def test_a_render_equals_avp_render(cli_render, scene, arm):
    q = scene.start_joints
    frame = scene.render(joints=q)
    out = cli_render
    with open(out / "camera.json") as f:
        camera = json.load(f)
    with open(out / "fruits.json") as f:
        fruits = json.load(f)
    h, w = frame["depth"].shape
    assert frame["rgb"].shape == (h, w, 3) and frame["rgb"].dtype == np.uint8
    assert frame["depth"].dtype == np.float32
    assert frame["instance"].dtype == np.uint16 and frame["class"].dtype == np.uint8
    np.testing.assert_allclose(frame["camera_pose"], arm.camera_pose(q), atol=1e-12)
    # The program's pose went through degrees and back.
    np.testing.assert_allclose(frame["camera_pose"], np.array(camera["X_WC"]["matrix"]),
                               atol=1e-9)
    # Per fruit, the same pixels as the program's render (fruit-class pixels per instance).
    fruit = frame["class"] == 1
    counts = np.bincount(frame["instance"][fruit], minlength=65536)
    listed = {f["instance_id"]: f["visible_pixels"] for f in fruits["fruits"]}
    assert sum(listed.values()) == int(fruit.sum()) > 0
    for instance, pixels in listed.items():
        assert counts[instance] == pixels, instance
    # A labelled pixel has a depth.
    assert (frame["depth"][frame["instance"] > 0] > 0).mean() > 0.9


def test_renders_are_seeded_and_noise_free_on_request(scene):
    a = scene.render(noise=True)
    b = scene.render(noise=True)
    np.testing.assert_array_equal(a["depth"], b["depth"])
    clean = scene.render(noise=False)
    assert not np.array_equal(a["depth"], clean["depth"])
    np.testing.assert_array_equal(a["class"], clean["class"])


def test_a_pose_and_a_camera_of_ones_own(scene, arm):
    pose = arm.camera_pose(scene.start_joints)
    small = avp.Camera(160, 120, fx=150.0, fy=150.0, cx=80.0, cy=60.0)
    frame = scene.render(camera_pose=pose, camera=small, noise=False)
    assert frame["depth"].shape == (120, 160)
    assert avp.Camera.d435().width == 640


def test_forward_and_inverse_kinematics(arm):
    q = (arm.lower_limits + arm.upper_limits) / 2 + 0.3
    pose = arm.camera_pose(q)
    assert pose.shape == (4, 4)
    solved = arm.camera_ik(pose, seed=1)
    assert solved is not None
    np.testing.assert_allclose(arm.camera_pose(solved), pose, atol=1e-4)
    assert arm.is_reachable(pose)
    far = np.eye(4)
    far[:3, 3] = [5.0, 0.0, 0.0]
    assert arm.camera_ik(far) is None and not arm.is_reachable(far)
    assert len(arm.joint_names) == len(arm.home) == 6


def test_bad_arrays_are_refused_by_name(scene, arm):
    with pytest.raises(TypeError, match="joints: dtype float32, expected float64"):
        arm.camera_pose(np.zeros(6, dtype=np.float32))
    with pytest.raises(ValueError, match=r"joints: shape \(5,\), expected \(6,\)"):
        arm.camera_pose(np.zeros(5))
    with pytest.raises(ValueError, match="limit"):
        arm.camera_pose(np.full(6, 100.0))
    with pytest.raises(ValueError, match="C-contiguous"):
        scene.render(camera_pose=np.eye(8)[::2, ::2])
    with pytest.raises(ValueError, match="not a rigid transform"):
        scene.render(camera_pose=np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="nan"):
        bad = np.eye(4)
        bad[0, 3] = np.nan
        scene.render(camera_pose=bad)
    with pytest.raises(TypeError, match="numpy array"):
        scene.render(camera_pose="eye")
    with pytest.raises(ValueError, match="not both"):
        scene.render(camera_pose=np.eye(4), joints=scene.start_joints)
    with pytest.raises(ValueError, match="fx"):
        avp.Camera(10, 10, fx=-1.0, fy=1.0, cx=5.0, cy=5.0)
    with pytest.raises(ValueError, match="tomatoo"):
        avp.Scene("tomatoo")
    with pytest.raises(FileNotFoundError, match="nothing.yaml"):
        avp.Scene(scene_file="nothing.yaml")


def test_segmentation_from_python_equals_avp_segment(avp_binary, tmp_root, scene, cli_render):
    frame = scene.render(joints=scene.start_joints)
    out = tmp_root / "cli-segment"
    # avp render wrote the same colour image (the noise is in the depth only).
    rgb = cli_render / "rgb.png"
    run_cli(avp_binary, "segment", "--backend", "color", "--image", rgb, "--prompt", "tomato",
            "--out", out)
    with open(out / "instances.json") as f:
        cli = json.load(f)["instances"]
    py = avp.segment(frame["rgb"], "tomato", backend="color")
    assert py["masks"].shape == (len(cli), 480, 640) and py["masks"].dtype == bool
    assert [int(m.sum()) for m in py["masks"]] == [i["area"] for i in cli]
    np.testing.assert_allclose(py["scores"], [i["score"] for i in cli], rtol=1e-6)
    assert py["labels"] == [i["label"] for i in cli]


def test_the_oracle_segments_a_render_with_its_scene(scene):
    frame = scene.render(joints=scene.start_joints)
    seg = avp.segment(frame, "tomato", backend="oracle", scene=scene, seed=1)
    assert len(seg["scores"]) > 0 and set(seg["class_names"]) <= {"fruit"}
    visible = set(np.unique(frame["instance"][frame["class"] == 1]).tolist())
    for m in seg["masks"]:
        # Each mask lies on one visible fruit, mostly.
        ids, counts = np.unique(frame["instance"][m], return_counts=True)
        assert ids[np.argmax(counts)] in visible
    again = avp.segment(frame, "tomato", backend="oracle", scene=scene, seed=1)
    np.testing.assert_array_equal(seg["masks"], again["masks"])


def test_segmentation_errors_name_the_value():
    with pytest.raises(TypeError, match=r"image: dtype float64, expected uint8"):
        avp.segment(np.zeros((4, 4, 3)), "tomato")
    with pytest.raises(ValueError, match=r"image: shape \(4, 4\), expected \(n, n, 3\)"):
        avp.segment(np.zeros((4, 4), dtype=np.uint8), "tomato")
    with pytest.raises(ValueError, match="nope"):
        avp.segment(np.zeros((4, 4, 3), dtype=np.uint8), "tomato", backend="nope")
    with pytest.raises(ValueError, match="prompt"):
        avp.segment(np.zeros((4, 4, 3), dtype=np.uint8), "", backend="color")


def test_a_zero_shot_backend_equals_avp_segment(avp_binary, tmp_root):
    """ywes on the stub models (zsl/test/stubs): the same instances as `avp segment`."""
    stubs = os.environ.get("AVP_ZSL_STUBS")
    if not stubs:
        pytest.skip("no ONNX Runtime in this build: AVP_ZSL_STUBS is not set (ctest sets it)")
    image = np.empty((768, 1024, 3), dtype=np.uint8)
    image[:] = (200, 50, 10)
    ppm = tmp_root / "stub-image.ppm"
    ppm.write_bytes(b"P6\n1024 768\n255\n" + image.tobytes())
    out = tmp_root / "cli-ywes"
    run_cli(avp_binary, "segment", "--image", ppm, "--prompt", "a, b", "--backend",
            f"ywes://{stubs}/ywes", "--out", out)
    with open(out / "instances.json") as f:
        cli = json.load(f)["instances"]
    py = avp.segment(image, "a, b", backend=f"ywes://{stubs}/ywes")
    assert len(cli) == 2 and py["labels"] == [i["label"] for i in cli]
    assert [int(m.sum()) for m in py["masks"]] == [i["area"] for i in cli]
    np.testing.assert_allclose(py["boxes"], [i["box"] for i in cli], atol=1e-3)
    np.testing.assert_allclose(py["scores"], [i["score"] for i in cli], rtol=1e-6)


def test_a_remote_segmenter_equals_the_same_segmenter_here(avp_binary, tmp_root):
    """`avp serve segmentation` on loopback: remote://.../color gives the local color masks."""
    port_file = tmp_root / "serve.port"
    port_file.unlink(missing_ok=True)
    server = subprocess.Popen([avp_binary, "serve", "segmentation", "--port", "0", "--backend",
                               "color", "--port-file", str(port_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not port_file.exists() and time.monotonic() < deadline and server.poll() is None:
            time.sleep(0.05)
        assert port_file.exists(), server.stderr.read() if server.poll() is not None else "no port"
        port = int(port_file.read_text())
        # Two red disks on green leaves: what the colour segmenter finds.
        yy, xx = np.mgrid[0:240, 0:320]
        image = np.empty((240, 320, 3), dtype=np.uint8)
        image[:] = (40, 140, 40)
        for cx, cy in ((80, 120), (230, 100)):
            image[(xx - cx) ** 2 + (yy - cy) ** 2 < 30 ** 2] = (200, 30, 20)
        remote = avp.segment(image, "tomato", backend=f"remote://127.0.0.1:{port}/color")
        local = avp.segment(image, "tomato", backend="color")
        assert len(local["scores"]) > 0
        np.testing.assert_array_equal(remote["masks"], local["masks"])
        np.testing.assert_array_equal(remote["scores"], local["scores"])
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)
