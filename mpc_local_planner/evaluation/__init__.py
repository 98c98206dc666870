# SPDX-License-Identifier: Apache-2.0
"""Closed loops without ROS, metrics, figures, suites and the benchmark."""
