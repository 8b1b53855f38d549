"""rosbag2 bags: storage, QoS metadata, recording, playback and recovery."""
