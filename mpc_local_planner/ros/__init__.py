# SPDX-License-Identifier: Apache-2.0
"""The ROS 2 adapters: nodes, conversions, QoS, closed_loop; the only layer importing rclpy."""
