"""avp.Map: any map file as numpy arrays, equal to the map's own exports voxel for voxel."""

import struct

import numpy as np
import pytest

import avp


def read_binary_ply(path):
    """The vertices of an avp PLY export (binary_little_endian: float x, y, z, uchar red, green,
    blue, class, float confidence, ushort instance, observations) as columns."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    assert "format binary_little_endian 1.0" in header
    count = int(next(l for l in header.splitlines() if l.startswith("element vertex")).split()[2])
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                      ("blue", "u1"), ("class", "u1"), ("confidence", "<f4"),
                      ("instance", "<u2"), ("observations", "<u2")])
    assert len(data) - end == count * dtype.itemsize
    return np.frombuffer(data, dtype=dtype, offset=end, count=count)


@pytest.mark.parametrize("which", ["occupied", "labelled", "all-labelled"])
def test_voxels_equal_the_ply_export_voxel_for_voxel(episode, tmp_root, which):
    m = episode.map
    v = m.voxels(which)
    out = tmp_root / f"map-{which}.ply"
    summary = m.export(out, voxels=which)
    assert summary["format"] == "ply"
    ply = read_binary_ply(out)
    assert len(v["x"]) == len(ply) > 0
    for axis in "xyz":
        np.testing.assert_array_equal(v[axis].astype(np.float32), ply[axis])
    for name in ("class", "confidence", "instance", "observations"):
        np.testing.assert_array_equal(v[name], ply[name])
    if which != "all-labelled":
        assert v["occupied"].all()
    # Centres lie on the voxel lattice of the keys.
    s = m.voxel_size_m
    np.testing.assert_allclose(v["x"], (v["i"] + 0.5) * s, atol=1e-9)
    np.testing.assert_allclose(m.centers(which), np.stack([v["x"], v["y"], v["z"]], axis=1))


def test_maps_read_from_octomap_files_hold_the_same_occupied_voxels(episode, tmp_root):
    m = episode.map
    assert m.format == "avpmap" and m.has_labels
    ot = avp.Map.load(episode.folder / "map.ot")
    assert ot.format == "ot"
    assert ot.voxel_size_m == pytest.approx(m.voxel_size_m)
    a = m.voxels("occupied")
    b = ot.voxels("occupied")
    key = lambda v: set(zip(v["i"].tolist(), v["j"].tolist(), v["k"].tolist()))
    assert key(a) == key(b)
    bt_path = tmp_root / "map.bt"
    m.export(bt_path)
    bt = avp.Map.load(bt_path)
    assert bt.format == "bt" and not bt.has_labels
    assert key(bt.voxels("occupied")) == key(a)
    # The known region: free and occupied voxels, with log-odds on the right side of the
    # threshold.
    known = m.voxels("known")
    assert len(known["x"]) == m.known_voxels > m.occupied_voxels == int(known["occupied"].sum())
    assert (known["log_odds"][known["occupied"]] > known["log_odds"][~known["occupied"]].max()).all()


def test_compare_against_itself_and_against_the_runs_truth(episode):
    m = episode.map
    fruit = m.voxels("labelled")
    assert (fruit["class"] > 0).all()
    same = m.compare(episode.folder / "map.avpmap", tolerance_voxels=1)
    assert same["exact"]["f1"] == 1.0 and same["exact"]["fp"] == 0 and same["exact"]["fn"] == 0
    assert same["tolerance"]["tolerance_voxels"] == 1
    # Against the .ot export (its classes read back from the colours): the same voxels.
    ot = m.compare(avp.Map.load(episode.folder / "map.ot"))
    assert ot["gt_used_labels"]
    assert ot["exact"]["tp"] == same["exact"]["tp"]


def test_instances_and_bounds(episode):
    m = episode.map
    bounds = m.known_bounds
    assert bounds.shape == (2, 3) and (bounds[1] > bounds[0]).all()
    inst = m.instances()
    ids = set(m.voxels("labelled")["instance"].tolist()) - {0}
    assert {i["id"] for i in inst} >= ids


def test_bad_map_files_raise_python_errors_naming_them(tmp_root):
    with pytest.raises(FileNotFoundError, match="nope.avpmap"):
        avp.Map.load(tmp_root / "nope.avpmap")
    junk = tmp_root / "junk.avpmap"
    junk.write_text("not a map\n")
    with pytest.raises(ValueError, match="junk.avpmap"):
        avp.Map.load(junk)


def test_bad_arguments_raise_value_errors(episode, tmp_root):
    m = episode.map
    with pytest.raises(ValueError, match="'everything'"):
        m.voxels("everything")
    with pytest.raises(ValueError, match="'banana'"):
        m.compare(episode.folder / "map.avpmap", cls="banana")
    with pytest.raises(ValueError, match="map file"):
        m.export(episode.folder / "map.avpmap")  # the file it came from
