"""avp.Recording: an episode recorded as MCAP, read back message by message as numpy arrays,
maps and JSON, equal to what the run wrote."""

import collections
import json

import numpy as np
import pytest

import avp
from conftest import SCENARIO

COLOR = "/camera/camera/color/image_raw"
DEPTH = "/camera/camera/aligned_depth_to_color/image_raw"


@pytest.fixture(scope="module")
def recorded(tmp_root):
    return avp.run(tmp_root / "recorded", scenario=SCENARIO, seed=2, episode={"views": 2},
                   record=True, record_compression="zstd", progress=False)


def keys(v):
    return set(zip(v["i"].tolist(), v["j"].tolist(), v["k"].tolist()))


def test_every_message_is_read_and_counted(recorded):
    rec = avp.Recording(recorded.folder / "episode.mcap")
    info = rec.info
    assert "MCAP" in info["format"] and COLOR in info["topics"]
    counts = collections.Counter(m.topic for m in rec)
    assert dict(counts) == {t: n for t, n in info["counts"].items() if n > 0}
    assert counts[COLOR] == 2
    assert info["metadata"]["avp"]["scene"] == SCENARIO
    truth = json.loads(rec.attachment("ground_truth.json"))
    assert truth


def test_images_are_the_views_the_episode_saw(recorded):
    rec = avp.Recording(recorded.folder / "episode.mcap")
    steps = [json.loads(m.decode()) for m in rec.messages(["/avp/step"])]
    colours = [m.decode() for m in rec.messages([COLOR])]
    assert len(steps) == len(colours) == 2
    pose = np.vstack([np.array(steps[0]["X_WC"]).reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
    frame = avp.Scene(SCENARIO, seed=2).render(camera_pose=pose, noise=False)
    np.testing.assert_array_equal(colours[0], frame["rgb"])  # colour carries no noise
    depth = next(iter(rec.messages([DEPTH]))).depth()
    assert depth.dtype == np.float32 and depth.shape == (480, 640)
    seen = (depth > 0) & (frame["depth"] > 0)
    assert seen.mean() > 0.1
    assert np.median(np.abs(depth[seen] - frame["depth"][seen])) < 0.005  # the noise model's


def test_the_last_map_message_is_the_final_map(recorded):
    rec = avp.Recording(recorded.folder / "episode.mcap")
    maps = [m.decode() for m in rec.messages(["/avp/map"])]
    assert len(maps) == 2 and maps[-1].format == "bt"
    assert keys(maps[-1].voxels("occupied")) == keys(recorded.map.voxels("occupied"))
    assert maps[0].occupied_voxels < maps[-1].occupied_voxels


def test_other_messages_and_errors(recorded, tmp_root):
    rec = avp.Recording(recorded.folder / "episode.mcap")
    joints = next(iter(rec.messages(["/joint_states"]))).decode()
    assert len(joints["name"]) == 6 and joints["position"].shape == (6,)
    tf = next(iter(rec.messages(["/tf"]))).decode()
    assert tf and tf[0]["transform"].shape == (4, 4)
    info = next(iter(rec.messages(["/camera/camera/color/camera_info"]))).decode()
    assert info["width"] == 640 and info["k"].shape == (3, 3)
    with pytest.raises(ValueError, match="not a sensor_msgs/msg/Image"):
        next(iter(rec.messages(["/avp/step"]))).depth()
    with pytest.raises(FileNotFoundError, match="nothing.mcap"):
        avp.Recording(tmp_root / "nothing.mcap")
    with pytest.raises(ValueError, match="no attachment 'x'"):
        rec.attachment("x")
    # A truncated copy: the intact messages, then an error naming where it stops.
    data = (recorded.folder / "episode.mcap").read_bytes()
    cut = tmp_root / "cut.mcap"
    cut.write_bytes(data[: len(data) * 9 // 10])
    read = 0
    with pytest.raises((ValueError, OSError)):
        for _ in avp.Recording(cut):
            read += 1
    assert read > 0
