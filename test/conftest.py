# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Shared test fixtures: the real data beside the project and isolated rclpy contexts.

The harness (node processes, probes, ``spin_until``, percentiles) is
``mv3dpose_ros.testing``, shared with the benchmarks.
"""

import os
import random

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED_DATA = os.path.join(os.path.dirname(ROOT), 'shared', 'data')

# DDS isolation for direct pytest runs (scripts/run_tests.sh sets these for make test).
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 199)))


@pytest.fixture(scope='session')
def shared_data():
    """Path of ../shared/data; tests that need it skip with a reason when it is absent."""
    if not os.path.isdir(SHARED_DATA):
        pytest.skip(f'real data not found at {SHARED_DATA} (../shared beside the project)')
    return SHARED_DATA


@pytest.fixture(scope='session')
def model():
    """Path of the default pose model; tests that run it skip with a reason when not fetched."""
    from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
    try:
        return resolve_model_path('yolo11n-pose')
    except ModelNotFound as exc:
        pytest.skip(str(exc))


@pytest.fixture
def ros_context():
    """Provide an initialised rclpy context of its own, shut down after the test."""
    rclpy = pytest.importorskip('rclpy')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)
