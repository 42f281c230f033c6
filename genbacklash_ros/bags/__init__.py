"""Recorded data: rosbag2/MCAP and CSV files, synthetic bags, offline replay.

Replay drives the node's own pipeline (:mod:`genbacklash_ros.node.pipeline`) from a file.
"""
