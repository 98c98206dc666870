# SPDX-License-Identifier: Apache-2.0
"""What the simulator and the suites simulate, without rclpy: the robot's world, not its mind.

The plant (`base.Base`, a kinematic unicycle as real as its `reality.Reality` says, with the
presets), the laser (`laser.SimulatedLaser`, casting against the true world through
perception's `TrueGeometry`) and its faults (`scan_channel.ScanChannel`), a localizer standing
in for AMCL (`localizer.Localizer`), and the contacts of the robot's true footprint
(`contact`). The unicycle_simulator node and the ROS-free rollout step the same objects, so
the suites measure what the nodes see. Nothing on the robot's side (core/, perception/)
imports this layer.
"""
