"""A ROS1 bag cut short (no index at its end) keeps every whole message before the cut and
says what it dropped: the sequential reader on a small bag written here, cut at many points,
and the hive importer on the shared bag cut into a temporary copy (skipped without
../shared; never kept)."""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.importers.hive import read_hive_bag
from lhgraph.importers.hive.salvage import salvage_bag


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    """600 std_msgs/Float64 messages in chunks of a few messages each (after the bag header's
    4 KiB)."""
    from rosbags.rosbag1 import Writer

    store = _typestore()
    Float64 = store.types["std_msgs/msg/Float64"]
    path = tmp_path_factory.mktemp("bag") / "small.bag"
    with Writer(path) as writer:
        writer.chunk_threshold = 200  # many small chunks (rosbags: 1 MiB by default)
        conn = writer.add_connection("/x", Float64.__msgtype__, typestore=store)
        for i in range(600):
            writer.write(conn, 1_000_000_000 + i * 1000,
                         store.serialize_ros1(Float64(data=float(i)), Float64.__msgtype__))
    return path


def test_a_whole_bag_reads_whole_without_its_index(small_bag):
    s = salvage_bag(small_bag, _typestore())
    assert [m.data for _, m in s.messages] == [float(i) for i in range(600)]
    assert all(topic == "/x" for topic, _ in s.messages)


@pytest.mark.parametrize("fraction", [0.3, 0.5, 0.7])
def test_a_cut_bag_keeps_the_whole_chunks_before_the_cut(small_bag, tmp_path, fraction):
    data = small_bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:int(len(data) * fraction)])
    s = salvage_bag(cut, _typestore())
    values = [m.data for _, m in s.messages]
    assert values == [float(i) for i in range(len(values))]  # a prefix, in order
    assert 0 < len(values) < 600 and s.kept_bytes <= s.size == cut.stat().st_size


def test_the_shared_hive_bag_cut_short_imports_its_prefix(hive_bag, tmp_path, capsys):
    whole = read_hive_bag(hive_bag)
    cut = tmp_path / "cut.bag"
    with hive_bag.open("rb") as f:
        cut.write_bytes(f.read(int(hive_bag.stat().st_size * 0.6)))
    part = read_hive_bag(cut)
    assert len(part.notes) == 1 and "cut short (no index)" in part.notes[0]
    n, m = len(part.light["time"]), len(part.imu_time)
    assert 0.3 * len(whole.light["time"]) < n < len(whole.light["time"])
    np.testing.assert_array_equal(part.light["angle"], whole.light["angle"][:n])
    np.testing.assert_array_equal(part.imu_time, whole.imu_time[:m])
    assert part.serials == whole.serials
    # the command imports it, exit 0, and says what was dropped even when quiet
    assert main(["import", "hive", str(cut), "-o", str(tmp_path / "o"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "cut short (no index)" in err and "dropped the last" in err
    assert (tmp_path / "o" / "angles.csv").exists()
