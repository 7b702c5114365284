"""Peer readers for benches/formats.rs: every IMU message of a log read and decoded to
numbers with the Python tools users have.

    python3 read_logs.py rosbag1|ulog|dataflash FILE

rosbag1: rosbags.rosbag1.Reader and rosbags.typesys (ROS1_NOETIC) deserialising each
sensor_msgs/Imu; ulog: pyulog's ULog(file, ['sensor_combined']); dataflash: pymavlink's
DFReader_binary iterating recv_match(type='IMU'). Prints the sample count and the sums
of the six channels (so the decoding cannot be skipped and the counts can be compared).
"""

import sys


def rosbag1(path):
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    n, s = 0, [0.0] * 6
    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/Imu"]
        for conn, _, raw in reader.messages(connections=conns):
            m = store.deserialize_ros1(raw, conn.msgtype)
            w, a = m.angular_velocity, m.linear_acceleration
            for k, v in enumerate((w.x, w.y, w.z, a.x, a.y, a.z)):
                s[k] += v
            n += 1
    return n, s


def ulog(path):
    from pyulog import ULog

    data = ULog(path, ["sensor_combined"]).get_dataset("sensor_combined").data
    names = [f"gyro_rad[{k}]" for k in range(3)] + [f"accelerometer_m_s2[{k}]" for k in range(3)]
    return len(data["timestamp"]), [float(data[c].astype("float64").sum()) for c in names]


def dataflash(path):
    from pymavlink.DFReader import DFReader_binary

    log = DFReader_binary(path)
    n, s = 0, [0.0] * 6
    while True:
        m = log.recv_match(type="IMU")
        if m is None:
            break
        for k, v in enumerate((m.GyrX, m.GyrY, m.GyrZ, m.AccX, m.AccY, m.AccZ)):
            s[k] += v
        n += 1
    return n, s


if __name__ == "__main__":
    kind, path = sys.argv[1], sys.argv[2]
    n, sums = {"rosbag1": rosbag1, "ulog": ulog, "dataflash": dataflash}[kind](path)
    print(f"samples {n} sums " + " ".join(f"{v:.6g}" for v in sums))
